// SPDX-License-Identifier: MIT
#pragma once
// Ranges of ids that a scan over all ids leaves out: the vertex ids whose
// records shrink_to_fit() gave back to the OS (Impl::released_ranges). They
// are all free and all-zero, so a scan for live vertices loses nothing by
// skipping them, and reading them would cost time in proportion to the
// largest mesh ever held and, on a kernel without a shared zero page, commit
// their pages again.
// Encoding: IdRange{first, end} is the ids [first, end). A skip list is
// sorted by first, its ranges non-empty and disjoint (checked in debug builds
// by for_each_kept).
#include <algorithm>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <span>

namespace pdt::detail {

struct IdRange {
  std::uint32_t first, end;
};

// Calls f(b, e) for each maximal range [b, e) of [begin, end) that no range
// of `skip` touches, in increasing order.
template <class F>
void for_each_kept(std::size_t begin, std::size_t end, std::span<const IdRange> skip, F&& f) {
  assert(std::adjacent_find(skip.begin(), skip.end(), [](IdRange a, IdRange b) { return a.end > b.first; }) ==
         skip.end());
  auto at = std::partition_point(skip.begin(), skip.end(), [&](IdRange r) { return r.end <= begin; });
  for (; begin < end && at != skip.end() && at->first < end; ++at) {
    assert(at->first < at->end);
    if (at->first > begin) f(begin, static_cast<std::size_t>(at->first));
    begin = std::max<std::size_t>(begin, at->end);
  }
  if (begin < end) f(begin, end);
}

}  // namespace pdt::detail
