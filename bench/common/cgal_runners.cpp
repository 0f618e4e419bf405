// SPDX-License-Identifier: MIT
#ifndef CGAL_LINKED_WITH_TBB
#define CGAL_LINKED_WITH_TBB 1  // CGAL's Parallel_tag code paths; the benches link TBB
#endif
#include "common/cgal_runners.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_lock_grid_3.h>
#include <CGAL/Triangulation_data_structure_3.h>
#include <CGAL/Triangulation_vertex_base_3.h>
#include <oneapi/tbb/task_arena.h>

#include <boost/iterator/transform_iterator.hpp>
#include <unordered_map>

#include "common/bench_util.hpp"
#include "support/sys_info.hpp"

namespace pdt_bench {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using CgalDT = CGAL::Delaunay_triangulation_3<K, CGAL::Default, CGAL::Fast_location>;
using CgalBatchDT = CGAL::Delaunay_triangulation_3<K>;
using ParTds = CGAL::Triangulation_data_structure_3<CGAL::Triangulation_vertex_base_3<K>,
                                                   CGAL::Delaunay_triangulation_cell_base_3<K>, CGAL::Parallel_tag>;
using LockGrid = CGAL::Spatial_lock_grid_3<CGAL::Tag_priority_blocking>;
using CgalParDT = CGAL::Delaunay_triangulation_3<K, ParTds, CGAL::Default, LockGrid>;
using pdt::support::Stopwatch;

std::vector<K::Point_3> to_cgal(const std::vector<pdt::Point3>& pts) {
  std::vector<K::Point_3> c;
  c.reserve(pts.size());
  for (const auto& p : pts) c.emplace_back(p.x, p.y, p.z);
  return c;
}

// pdt's points as CGAL's, one at a time, for insert(first, last).
struct ToCgal {
  K::Point_3 operator()(const pdt::Point3& p) const { return {p.x, p.y, p.z}; }
};
auto cgal_begin(const std::vector<pdt::Point3>& pts) { return boost::make_transform_iterator(pts.begin(), ToCgal{}); }
auto cgal_end(const std::vector<pdt::Point3>& pts) { return boost::make_transform_iterator(pts.end(), ToCgal{}); }

double rss() { return static_cast<double>(pdt::support::current_rss_bytes()); }

}  // namespace

CgalRun cgal_sequential(const std::vector<pdt::Point3>& pts, const std::vector<char>& removes) {
  CgalRun r;
  settle();
  {
    const std::size_t n_remove = removes.size();
    std::vector<K::Point_3> cpts = to_cgal(pts);
    std::vector<CgalDT::Vertex_handle> vh(n_remove);
    settle();
    const double rss0 = rss();
    CgalDT dt;
    Stopwatch sw;
    for (std::size_t k = 0; k < cpts.size(); ++k) {
      CgalDT::Vertex_handle v = dt.insert(cpts[k]);
      if (k < n_remove) vh[k] = v;
    }
    r.insert_seconds = sw.seconds();
    const double rss1 = rss();
    r.rss_insert = rss1 - rss0;
    r.shape.cells_after_insert = dt.number_of_finite_cells();
    r.cells_after_insert_all = dt.number_of_cells();
    sw.restart();
    for (std::size_t k = 0; k < n_remove; ++k)
      if (removes[k]) dt.remove(vh[k]);
    r.remove_seconds = sw.seconds();
    r.rss_remove = rss() - rss1;
    r.shape.finite_cells = dt.number_of_finite_cells();
    r.shape.vertices = dt.number_of_vertices();
  }
  settle();
  return r;
}

CgalRun cgal_sequential_stream(const pdt::OpStream& s) {
  CgalRun r;
  settle();
  {
    // Which removals make a vertex disappear (CGAL has no multiplicity).
    std::vector<char> really(s.ops.size(), 1);
    std::vector<K::Point_3> ins_pts;
    {
      std::vector<pdt::Point3> inserted;
      std::unordered_map<pdt::Point3, std::uint32_t, PointHash> count;
      for (std::size_t i = 0; i < s.ops.size(); ++i) {
        const pdt::Operation& op = s.ops[i];
        if (op.kind == pdt::Operation::Kind::insert) {
          inserted.push_back(op.point);
          ++count[op.point];
        } else {
          really[i] = --count[inserted[op.target]] == 0;
        }
      }
      ins_pts = to_cgal(inserted);
    }
    std::vector<CgalDT::Vertex_handle> vh(ins_pts.size());
    CgalDT dt;
    std::size_t next = 0;
    Stopwatch sw;
    for (std::size_t i = 0; i < s.ops.size(); ++i) {
      const pdt::Operation& op = s.ops[i];
      if (op.kind == pdt::Operation::Kind::insert) {
        vh[next] = dt.insert(ins_pts[next]);
        ++next;
      } else if (really[i]) {
        dt.remove(vh[op.target]);
      }
    }
    r.mixed_seconds = sw.seconds();
    r.shape.finite_cells = dt.number_of_finite_cells();
    r.shape.vertices = dt.number_of_vertices();
  }
  settle();
  return r;
}

double cgal_batch_insert(const std::vector<pdt::Point3>& pts, std::size_t* cells) {
  double seconds = 0;
  settle();
  {
    std::vector<K::Point_3> cpts = to_cgal(pts);
    CgalDT dt;
    Stopwatch sw;
    dt.insert(cpts.begin(), cpts.end());
    seconds = sw.seconds();
    if (cells) *cells = dt.number_of_cells();
  }
  settle();
  return seconds;
}

CgalInsert cgal_range_insert(const std::vector<pdt::Point3>& pts, const pdt::Box& box, unsigned threads) {
  CgalInsert r;
  auto insert_all = [&](auto& dt) {
    Stopwatch sw;
    dt.insert(cgal_begin(pts), cgal_end(pts));
    r.seconds = sw.seconds();
    r.vertices = dt.number_of_vertices();
    r.finite_cells = dt.number_of_finite_cells();
  };
  if (threads == 0) {
    CgalBatchDT dt;
    insert_all(dt);
    return r;
  }
  tbb::task_arena arena(static_cast<int>(threads));
  LockGrid lock(CGAL::Bbox_3(box.lo.x, box.lo.y, box.lo.z, box.hi.x, box.hi.y, box.hi.z), lock_grid_cells_per_axis);
  CgalParDT dt(&lock);
  arena.execute([&] { insert_all(dt); });
  return r;
}

CgalRun cgal_parallel(const std::vector<pdt::Point3>& pts, const pdt::Box& box, const std::vector<char>& removes,
                      unsigned threads) {
  CgalRun r;
  settle();
  {
    const std::size_t n_remove = removes.size();
    std::vector<K::Point_3> cpts = to_cgal(pts);
    tbb::task_arena arena(static_cast<int>(threads));
    LockGrid lock(CGAL::Bbox_3(box.lo.x, box.lo.y, box.lo.z, box.hi.x, box.hi.y, box.hi.z), lock_grid_cells_per_axis);
    CgalParDT dt(&lock);
    arena.execute([&] {
      Stopwatch sw;
      dt.insert(cpts.begin(), cpts.end());
      r.insert_seconds = sw.seconds();
    });
    r.shape.cells_after_insert = dt.number_of_finite_cells();

    // The handles of the first n_remove points (untimed): through a point -> vertex map.
    std::vector<CgalParDT::Vertex_handle> to_remove;
    {
      std::unordered_map<pdt::Point3, CgalParDT::Vertex_handle, PointHash> where;
      where.reserve(dt.number_of_vertices() * 2);
      for (auto v = dt.finite_vertices_begin(); v != dt.finite_vertices_end(); ++v) {
        const K::Point_3& p = v->point();
        where.emplace(pdt::Point3{p.x(), p.y(), p.z()}, v);
      }
      to_remove.reserve(n_remove);
      for (std::size_t k = 0; k < n_remove; ++k)
        if (removes[k]) to_remove.push_back(where.at(pts[k]));
    }
    settle();
    arena.execute([&] {
      Stopwatch sw;
      dt.remove(to_remove.begin(), to_remove.end());
      r.remove_seconds = sw.seconds();
    });
    r.shape.finite_cells = dt.number_of_finite_cells();
    r.shape.vertices = dt.number_of_vertices();
  }
  settle();
  return r;
}

}  // namespace pdt_bench
