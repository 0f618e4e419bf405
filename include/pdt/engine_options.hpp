// SPDX-License-Identifier: MIT
#pragma once
// pdt::EngineOptions: how an Engine splits its work. Every field is mirrored by
// an environment variable, read by EngineOptions::from_environment().
#include <cstddef>

namespace pdt {

struct EngineOptions {
  static constexpr unsigned max_workers = 4096;
  static constexpr unsigned max_blocks_per_axis = 64;
  // PDT_WORKERS: the engine's workers (at most max_workers), 0 = the arena's
  // concurrency. Workers are
  // C++20 coroutines run as oneTBB tasks, not threads: how many threads run
  // them is the task_arena's business (its concurrency), so 16 workers in an
  // arena of 2 threads is fine (and tests every interleaving the locks allow).
  unsigned workers = 0;
  // PDT_BLOCKS_PER_AXIS: the domain is cut into b^3 blocks (at most 64 per
  // axis); 0 = the smallest b with b^3 >= 64 * workers, so that a worker can
  // take over part of a busy region, and b^3 >= 512 at any worker count: a
  // worker serves a block's queued operations one after the other, and a
  // smaller block's share of the mesh stays in the core's cache meanwhile
  // (1M points submitted singly, 1 worker: 8 per axis 11% faster than 4).
  unsigned blocks_per_axis = 0;
  double contention_low = 0.7;      // PDT_CONTENTION_LOW: u-, sleep below this progress ratio
  double contention_high = 0.9;     // PDT_CONTENTION_HIGH: u+, wake a sleeper above it
  unsigned contention_window = 32;  // PDT_CONTENTION_WINDOW: attempts between two judgements (0 counts as 1)
  std::size_t grid_slots = 1u << 23;  // PDT_GRID_SLOTS: most slots of the jump-and-walk grid, which
                                      // grows with the vertex count (about 2 vertices per slot; 0
                                      // counts as 1)
  // PDT_ESCALATE_AFTER: an operation rolled back this many times runs with
  // the world stopped (alone), so none starves (0 = never escalate).
  unsigned escalate_after = 64;
  // PDT_STEALING (0 or 1): a worker with nothing at home serves other
  // workers' blocks. Off: each block is served by its home worker only
  // (the paper's static partition).
  bool stealing = true;
  // Deprecated: the older name of `workers` (it counts workers, not
  // threads); used only when workers is 0. PDT_THREADS is read into workers.
  unsigned threads = 0;
  // PDT_REBALANCE (0 or 1), with stealing: when queued work piles up in the
  // few blocks other workers already serve (a cluster, a front) while a
  // worker has nothing to do, that worker re-cuts the blocks at quantiles of
  // the queued operations (the world stopped for a moment), so that every
  // block, and every worker's home, holds about the same work. Routing only:
  // the result is the same triangulation either way.
  bool rebalance = true;

  // Starts from `defaults` and overrides each field whose variable is set
  // to a non-empty value (an empty one counts as unset): a plain decimal
  // number (digits and at most one '.', then for the contention thresholds
  // an optional exponent: no sign, spaces, hex or "inf"; whole for integer
  // fields), in the field's range (contention thresholds and the 0/1 flags
  // included). Throws pdt::Error(invalid_argument) naming the variable and
  // the range for a bad value.
  static EngineOptions from_environment(EngineOptions defaults);
  static EngineOptions from_environment();
};

// The per-thread pool allocator this build uses for cells and vertices:
// "pool" (pdt's chunked pool) or "mimalloc" (CMake option PDT_ALLOCATOR).
const char* allocator_name();

}  // namespace pdt
