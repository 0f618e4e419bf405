// SPDX-License-Identifier: MIT
#pragma once
// for_range(n, parallel, body): body(begin, end) over [0, n), in pieces of
// 16k on the current TBB arena's threads when parallel, else once over the
// whole range on this thread. Callers that run it inside work that must not
// take unrelated tasks (the engine's stopped world) isolate it themselves.
#include <cstddef>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

namespace pdt::detail {

template <class Body>
void for_range(std::size_t n, bool parallel, const Body& body) {
  if (parallel)
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 14),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  else
    body(std::size_t{0}, n);
}

}  // namespace pdt::detail
