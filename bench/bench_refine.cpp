// SPDX-License-Identifier: MIT
// bench_refine: Delaunay refinement (the rules of `pdt refine`, tools/refine)
// on CGAL's Delaunay_triangulation_3 (sequential, Fast_location) and on pdt's
// engine with 1, 2, ... workers, same domain, size, ratio and surface samples.
//
//   bench_refine [--domain torus] [--size 0.04] [--ratio 2] [--threads 1,2] [--seed 1]
//
// CGAL runs the same decisions one at a time: a FIFO queue of bad cells
// (circumcentre inside, circumradius > size or radius-edge > ratio), each
// checked alive when its turn comes (its four vertices and their points
// unchanged); a circumcentre within a sample's snap radius is replaced by that
// sample if it is not in yet (the cell judged again), else skipped; every
// insertion judges the cells incident to the new vertex (those it made); a
// sample's insertion removes the non-sample vertices of those cells within its
// protecting radius (remove_and_give_new_cells, whose cells are judged). When
// the queue empties, the samples not in yet go in as one batch, and
// refinement resumes. The start is pdt refine's: the box's corners, then a
// jittered lattice well inside.
//
// Every configuration runs in a child process (fork), so its peak memory is
// its own (getrusage of the child). The result is judged independently for
// both (pdt_refine::measure): the bounds must hold outside the protected
// layer. The two refinements make different (equally valid) decisions in a
// different order, so their vertex counts differ by a few percent.
// CGAL 5.5's Triangulation_hierarchy_3::remove_and_give_new_cells does not
// compile with its preconditions on (an unqualified is_infinite in a
// dependent base), as in the sanitizer builds, which keep assertions: the
// triangulation's preconditions are off here. pdt's own checks are not affected.
#define CGAL_TRIANGULATION_NO_PRECONDITIONS
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/version.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <deque>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "common/bench_util.hpp"
#include "common/child.hpp"
#include "common/report.hpp"
#include "pdt/error.hpp"
#include "pdt/triangulation.hpp"
#include "refine/domain.hpp"
#include "refine/quality.hpp"
#include "refine/refiner.hpp"
#include "refine/samples.hpp"
#include "support/sys_info.hpp"

namespace {

using namespace pdt_bench;
using pdt::Point3;
using pdt::support::Stopwatch;

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Dt = CGAL::Delaunay_triangulation_3<K, CGAL::Default, CGAL::Fast_location>;
using CellH = Dt::Cell_handle;
using VertexH = Dt::Vertex_handle;

struct Options {
  std::string domain = "torus";
  double size = 0.04;
  double ratio = 2;
  std::vector<unsigned> threads{1, 2};
  std::uint64_t seed = 1;
};

// What one configuration reports to the parent (plain data through a pipe).
struct Outcome {
  bool ok = false;
  char error[256] = {};
  double seconds = 0;
  std::uint64_t vertices = 0, tets_inside = 0, insertions = 0, removals = 0, rollbacks = 0;
  std::uint64_t judged = 0, violations = 0, finite_cells = 0;
  double worst_ratio = 0, largest_radius = 0, imbalance = 1;
  long peak_kib = 0;  // filled in by the parent
};

Point3 to_point(const K::Point_3& p) { return {p.x(), p.y(), p.z()}; }

// The sequential refiner on CGAL, the rules of pdt refine one at a time.
class CgalRefiner {
 public:
  CgalRefiner(const Options& o, const pdt_refine::Domain& d)
      : o_(o),
        d_(d),
        samples_(pdt_refine::surface_samples(d, o.size, o.seed), 0.5 * o.size),
        snap_(pdt_refine::snap_radius(o.size)),
        protect_(pdt_refine::protect_radius(o.size)) {}

  void run() {
    const pdt::Box& b = d_.box;
    for (int k = 0; k < 8; ++k)
      insert({k & 1 ? b.hi.x : b.lo.x, k & 2 ? b.hi.y : b.lo.y, k & 4 ? b.hi.z : b.lo.z}, false);
    // The same jittered lattice as pdt refine's start (tools/refine/refiner.cpp).
    const double h = 3 * o_.size;
    std::mt19937_64 rng(o_.seed ^ 0x5DEECE66Dull);
    std::uniform_real_distribution<double> jitter(-0.05 * h, 0.05 * h);
    for (double z = b.lo.z + h / 2; z < b.hi.z; z += h)
      for (double y = b.lo.y + h / 2; y < b.hi.y; y += h)
        for (double x = b.lo.x + h / 2; x < b.hi.x; x += h) {
          const Point3 p{x + jitter(rng), y + jitter(rng), z + jitter(rng)};
          if (d_.f(p) < -o_.size) insert(p, false);
        }
    for (CellH c : dt_.finite_cell_handles()) judge(c);
    bool surface_done = false;
    for (;;) {
      refine_queue();
      if (surface_done) break;
      surface_done = true;
      for (std::uint32_t i = 0; i < samples_.size(); ++i)
        if (samples_.claim(i)) insert(samples_[i], true);
    }
  }
  const Dt& dt() const { return dt_; }
  std::uint64_t insertions = 0, removals = 0;

 private:
  struct Bad {
    CellH c;
    std::array<VertexH, 4> v;
    std::array<Point3, 4> p;
    Point3 circumcentre;
  };
  void judge(CellH c) {
    if (dt_.is_infinite(c)) return;
    Bad b{c, {}, {}, {}};
    for (int i = 0; i < 4; ++i) b.v[i] = c->vertex(i), b.p[i] = to_point(c->vertex(i)->point());
    const pdt_refine::TetShape s = pdt_refine::shape(b.p);
    if (!s.ok || !(d_.f(s.circumcentre) < 0)) return;
    if (s.circumradius > o_.size || s.radius_edge > o_.ratio) {
      b.circumcentre = s.circumcentre;
      queue_.push_back(b);
    }
  }
  // Alive: the cell's slot is in use (CGAL's compact container marks freed
  // slots; a freed cell keeps its vertex pointers, so they alone cannot
  // tell) and holds the vertices, at the points, it was judged with (a
  // reused slot holds another cell).
  bool alive(const Bad& b) const {
    if (!dt_.tds().cells().is_used(b.c)) return false;
    for (int i = 0; i < 4; ++i)
      if (b.c->vertex(i) != b.v[i] || to_point(b.v[i]->point()) != b.p[i]) return false;
    return true;
  }
  void refine_queue() {
    while (!queue_.empty()) {
      const Bad b = queue_.front();
      queue_.pop_front();

      if (!alive(b)) continue;
      if (const std::int64_t near = samples_.nearest_within(b.circumcentre, snap_); near >= 0) {
        if (samples_.claim(static_cast<std::uint32_t>(near))) {
          insert(samples_[static_cast<std::uint32_t>(near)], true);
          queue_.push_back(b);
        }
        continue;
      }
      insert(b.circumcentre, false);
    }
  }
  void insert(const Point3& p, bool sample) {
    const std::size_t before = dt_.number_of_vertices();
    const VertexH v = dt_.insert(K::Point_3(p.x, p.y, p.z));
    ++insertions;
    if (dt_.number_of_vertices() == before) return;  // there already
    if (dt_.dimension() < 3) return;
    cells_.clear();
    dt_.incident_cells(v, std::back_inserter(cells_));
    std::vector<VertexH> doomed;
    for (CellH c : cells_) {
      judge(c);
      if (!sample) continue;
      for (int i = 0; i < 4; ++i) {
        const VertexH w = c->vertex(i);
        if (w == v || dt_.is_infinite(w)) continue;
        const Point3 q = to_point(w->point());
        if (pdt_refine::dist2(q, p) < protect_ * protect_ && !samples_.is_sample(q) &&
            std::find(doomed.begin(), doomed.end(), w) == doomed.end())
          doomed.push_back(w);
      }
    }
    for (VertexH w : doomed) {
      cells_.clear();
      dt_.remove_and_give_new_cells(w, std::back_inserter(cells_));
      ++removals;
      for (CellH c : cells_) judge(c);
    }
  }

  const Options& o_;
  const pdt_refine::Domain& d_;
  pdt_refine::Samples samples_;
  double snap_, protect_;
  Dt dt_;
  std::deque<Bad> queue_;
  std::vector<CellH> cells_;
};

Outcome run_cgal(const Options& o, const pdt_refine::Domain& d) {
  Outcome out;
  Stopwatch sw;
  CgalRefiner r(o, d);
  r.run();
  out.seconds = sw.seconds();
  out.insertions = r.insertions;
  out.removals = r.removals;
  // Judged independently, through a pdt triangulation of the same points
  // (the Delaunay triangulation of a point set is unique): pdt_refine::measure.
  std::vector<Point3> pts;
  for (auto v : r.dt().finite_vertex_handles()) pts.push_back(to_point(v->point()));
  pdt::Triangulation t;
  (void)t.insert_batch(pts);
  if (t.number_of_finite_cells() != r.dt().number_of_finite_cells())
    throw pdt::Error(pdt::ErrorCode::invalid_argument, "pdt's triangulation of CGAL's refined points differs");
  const pdt_refine::MeshQuality q = pdt_refine::measure(t, d, o.size, o.ratio, o.seed);
  out.vertices = r.dt().number_of_vertices();
  out.finite_cells = r.dt().number_of_finite_cells();
  out.tets_inside = q.inside;
  out.judged = q.judged;
  out.violations = q.violations;
  out.worst_ratio = q.worst_ratio;
  out.largest_radius = q.largest_radius;
  out.ok = true;
  return out;
}

Outcome run_pdt(const Options& o, const pdt_refine::Domain& d, unsigned workers) {
  Outcome out;
  pdt_refine::RefineOptions ro;
  ro.domain = d;
  ro.size = o.size;
  ro.ratio = o.ratio;
  ro.workers = workers;
  ro.seed = o.seed;
  pdt::Triangulation t;
  const pdt_refine::RefineStats st = pdt_refine::refine(t, ro);
  out.seconds = st.seconds;
  out.insertions = st.insertions;
  out.removals = st.removals;
  out.rollbacks = st.engine.total().rollbacks;
  out.imbalance = st.engine.imbalance();
  const pdt_refine::MeshQuality q = pdt_refine::measure(t, d, o.size, o.ratio, o.seed, workers);
  out.vertices = t.number_of_vertices();
  out.finite_cells = t.number_of_finite_cells();
  out.tets_inside = q.inside;
  out.judged = q.judged;
  out.violations = q.violations;
  out.worst_ratio = q.worst_ratio;
  out.largest_radius = q.largest_radius;
  out.ok = !st.budget_hit;
  if (st.budget_hit) std::snprintf(out.error, sizeof out.error, "the point budget was hit");
  return out;
}

// Runs fn in a child process (common/child.hpp); the child's peak RSS is the configuration's.
template <class Fn>
Outcome in_child(Fn fn) {
  Outcome out;
  const ChildStatus st = pdt_bench::in_child(fn, out);
  if (!st.ok) {
    out = Outcome{};
    std::snprintf(out.error, sizeof out.error, "%s", st.error.c_str());
  }
  out.peak_kib = st.peak_kib;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  ArgParser args(argv[0], "Delaunay refinement (pdt refine's rules) on CGAL sequential and on pdt's engine");
  args.text("--domain", "sphere, torus or gyroid (default torus)", o.domain);
  args.real("--size", "the circumradius bound (default 0.04)", o.size, 1e-6, 1e6);
  args.real("--ratio", "the radius-edge bound (default 2)", o.ratio, 2, 1e6);
  args.counts("--threads", "comma-separated worker counts for pdt (default 1,2)", o.threads, 1, 4096);
  args.count("--seed", "surface samples' seed (default 1)", o.seed);
  args.parse(argc, argv);
  pdt_refine::Domain d;
  try {
    d = pdt_refine::domain_by_name(o.domain);
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 2;
  }
  std::printf("bench_refine: domain %s, size %g, ratio %g, seed %llu\n", o.domain.c_str(), o.size, o.ratio,
              static_cast<unsigned long long>(o.seed));
  std::printf("machine: %u hardware threads (nproc %d), CPU %s; pdt allocator %s; CGAL %s\n",
              std::thread::hardware_concurrency(), affinity_cpus(), cpu_model().c_str(), pdt::allocator_name(),
              CGAL_VERSION_STR);
  std::printf("CGAL: Delaunay_triangulation_3<Epick, Default, Fast_location>, the same rules one at a time; "
              "pdt: pdt_refine::refine (pdt refine) on the engine. Each in its own process.\n\n");
  std::fflush(stdout);

  std::vector<std::string> names{"CGAL sequential"};
  std::vector<Outcome> rows;
  progress("CGAL sequential...\n");
  rows.push_back(in_child([&] { return run_cgal(o, d); }));
  for (unsigned w : o.threads) {
    progress("pdt, %u worker(s)...\n", w);
    names.push_back("pdt, " + std::to_string(w) + " worker" + (w == 1 ? "" : "s"));
    rows.push_back(in_child([&] { return run_pdt(o, d, w); }));
  }

  std::printf("%-18s %9s %11s %12s %10s %10s %9s %9s %10s %9s %10s %11s\n", "", "time (s)", "vs CGAL", "tets inside",
              "tets/s", "vertices", "inserts", "removals", "rollbacks", "imbal.", "peak MiB", "bounds");
  int bad = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Outcome& r = rows[i];
    if (!r.ok) {
      std::printf("%-18s FAILED: %s\n", names[i].c_str(), r.error);
      ++bad;
      continue;
    }
    const bool met = r.violations == 0;
    bad += !met;
    std::printf("%-18s %9.3f %11s %12s %10s %10s %9s %9s %10s %9s %10.1f %11s\n", names[i].c_str(), r.seconds,
                i == 0 ? "1.00" : fmt_ratio(rows[0].seconds, r.seconds).c_str(), fmt_u(r.tets_inside).c_str(),
                fmt_u(static_cast<std::uint64_t>(double(r.tets_inside) / r.seconds)).c_str(), fmt_u(r.vertices).c_str(),
                fmt_u(r.insertions).c_str(), fmt_u(r.removals).c_str(), i == 0 ? "-" : fmt_u(r.rollbacks).c_str(),
                i == 0 ? "-" : fmt("%.2f", r.imbalance).c_str(), double(r.peak_kib) / 1024, met ? "met" : "MISSED");
  }
  std::printf("\n'vs CGAL': CGAL's time / this one (above 1: faster than CGAL). 'bounds': every tetrahedron whose "
              "circumcentre is inside and outside the protected layer has circumradius <= size and radius-edge <= "
              "ratio (judged independently of the refiner). worst radius-edge:");
  for (const Outcome& r : rows) std::printf(" %.3f", r.worst_ratio);
  std::printf("\n");
  return bad ? 1 : 0;
}
