// SPDX-License-Identifier: MIT
#pragma once
// CGAL doing what pdt does, for the benches' comparisons: the same points, the
// same operations, timed the same way.
//   sequential  Delaunay_triangulation_3<Epick, Default, Fast_location>:
//               insert(p) one at a time (no spatial sort), remove(vh) one at a time
//   batch       the same triangulation, insert(first, last) (CGAL spatially
//               sorts the range, inside the timing)
//   range       Delaunay_triangulation_3<Epick> (no Fast_location: a batch
//               needs no hierarchy), insert(first, last) straight from pdt's
//               points; or the parallel one below, the same way
//   parallel    Parallel_tag TDS + Spatial_lock_grid_3<Tag_priority_blocking>,
//               in a tbb::task_arena(T): insert(range), then remove(range)
// CGAL's Parallel_tag containers allocate with tbb::scalable_allocator: the
// benches link TBB::tbbmalloc for it (CMakeLists.txt).
#include <cstddef>
#include <vector>

#include "pdt/geometry.hpp"
#include "pdt/ops.hpp"

namespace pdt_bench {

// The final state of a triangulation, to compare pdt with CGAL.
struct Shape {
  std::size_t cells_after_insert = 0;  // finite cells once every insertion is done
  std::size_t finite_cells = 0;        // at the end
  std::size_t vertices = 0;            // at the end
};

struct CgalRun {
  double insert_seconds = 0, remove_seconds = 0, mixed_seconds = 0;
  double rss_insert = 0, rss_remove = 0;  // resident-memory deltas of each phase, bytes
  std::size_t cells_after_insert_all = 0;  // finite + infinite
  Shape shape;
};

inline constexpr int lock_grid_cells_per_axis = 50;

// Inserts pts one at a time, then removes the first removes.size() insertions
// whose removes[k] is set (see last_removals).
CgalRun cgal_sequential(const std::vector<pdt::Point3>& pts, const std::vector<char>& removes);
// Replays a stream with insertions and removals mixed, one operation at a time.
CgalRun cgal_sequential_stream(const pdt::OpStream& s);
// insert(first, last): returns the time; *cells gets the number of cells.
double cgal_batch_insert(const std::vector<pdt::Point3>& pts, std::size_t* cells);
// The range insertion on its own (bench_peers): threads 0 = the sequential
// triangulation, else the parallel one in a tbb::task_arena(threads). The
// points go in through a converting iterator, so the only copy is CGAL's own
// (which it spatially sorts, inside the timing).
struct CgalInsert {
  double seconds = 0;
  std::size_t vertices = 0, finite_cells = 0;
};
CgalInsert cgal_range_insert(const std::vector<pdt::Point3>& pts, const pdt::Box& box, unsigned threads);
CgalRun cgal_parallel(const std::vector<pdt::Point3>& pts, const pdt::Box& box, const std::vector<char>& removes,
                      unsigned threads);

}  // namespace pdt_bench
