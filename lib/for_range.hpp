// SPDX-License-Identifier: MIT
#pragma once
// for_range(n, parallel, body): body(begin, end) over [0, n), in pieces of
// 16k on the current TBB arena's threads when parallel, else once over the
// whole range on this thread. Callers that run it inside work that must not
// take unrelated tasks (the engine's stopped world) isolate it themselves.
// Every piece runs, also when the caller's own TBB context is cancelled (a
// submission from a parallel loop whose sibling threw): the loop has a
// context of its own, else a cancelled caller would skip
// pieces silently, as an unchecked batch or an order of zeros. The other
// parallel loops of the caller's side (spatial_order.cpp, jump_grid.cpp)
// take such a context too.
#include <cstddef>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_group.h>

namespace pdt::detail {

template <class Body>
void for_range(std::size_t n, bool parallel, const Body& body) {
  if (parallel) {
    tbb::task_group_context own(tbb::task_group_context::isolated);  // a throw in body still ends the loop
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, n, 1 << 14),
        [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); }, tbb::auto_partitioner{}, own);
  } else {
    body(std::size_t{0}, n);
  }
}

}  // namespace pdt::detail
