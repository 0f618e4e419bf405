// SPDX-License-Identifier: MIT
// The box filter (lib/box_filter.hpp) decides orientation and in-sphere tests
// before CGAL's predicates: its sign must be CGAL's in every case, the
// degenerate and the badly scaled ones above all (tiny and huge boxes, a
// cluster of tiny differences inside a large box, where products underflow,
// boxes far from the origin, elongated boxes, exact ties).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <oneapi/tbb/task_arena.h>

#include "box_filter.hpp"
#include "pdt/engine.hpp"
#include "pdt/triangulation.hpp"
#include "predicates.hpp"
#include "triangulation_impl.hpp"

using pdt::detail::BoxFilter;
using pdt::detail::FilterEps;
using pdt::detail::KPoint;

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

struct Counts {
  long decided = 0;  // tests the box's epsilon decided (no call to CGAL)
  long tests = 0;
  long spheres_with_box = 0;    // in-sphere tests with a finite epsilon
  long undecided_spheres = 0;  // of those, the ones box_side_of_sphere left to CGAL
};

// Every orientation and in-sphere test among groups of pts, with the filter of
// a box holding them all, against CGAL's predicates.
void check_against_cgal(const std::vector<KPoint>& pts, std::mt19937_64& rng, Counts& counts, int groups = 400) {
  BoxFilter f;
  for (const KPoint& p : pts) f.extend(p);
  REQUIRE(f.check());
  const FilterEps e = f.eps();
  std::uniform_int_distribution<std::size_t> pick(0, pts.size() - 1);
  for (int g = 0; g < groups; ++g) {
    const KPoint& a = pts[pick(rng)];
    const KPoint& b = pts[pick(rng)];
    const KPoint& c = pts[pick(rng)];
    const KPoint& d = pts[pick(rng)];
    const KPoint& q = pts[pick(rng)];
    const int o = pdt::detail::filtered_orient(a, b, c, d, e.orient);
    INFO("points " << a << " | " << b << " | " << c << " | " << d << " | " << q << "; eps " << e.orient << ", "
                   << e.insphere);
    REQUIRE(o == static_cast<int>(CGAL::orientation(a, b, c, d)));
    const int s = pdt::detail::filtered_side_of_sphere(a, b, c, d, q, e.insphere);
    REQUIRE(s == static_cast<int>(CGAL::side_of_oriented_sphere(a, b, c, d, q)));
    // The verdict alone (gather_conflict_zone's first pass): CGAL's sign or
    // nothing, and nothing only where the box's epsilon does not decide.
    const int v = pdt::detail::box_side_of_sphere(a, b, c, d, q, e.insphere);
    REQUIRE((v == 0 || v == s));
    counts.spheres_with_box += e.insphere < inf;
    if (e.insphere < inf && v == 0) ++counts.undecided_spheres;
    counts.tests += 2;
    counts.decided += (o != 0 && e.orient < inf) + (s != 0 && e.insphere < inf);
  }
}

// n points: uniform in [lo, lo + extent]^3 per axis (extents per axis).
std::vector<KPoint> uniform(std::mt19937_64& rng, int n, const double lo[3], const double ext[3]) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<KPoint> pts;
  for (int i = 0; i < n; ++i) pts.emplace_back(lo[0] + ext[0] * u(rng), lo[1] + ext[1] * u(rng), lo[2] + ext[2] * u(rng));
  return pts;
}

// Points on a small integer lattice, scaled and shifted: exact ties of
// orientation (coplanar) and in-sphere (cospherical) abound.
std::vector<KPoint> lattice(std::mt19937_64& rng, int n, double lo, double step) {
  std::uniform_int_distribution<int> k(0, 3);
  std::vector<KPoint> pts;
  for (int i = 0; i < n; ++i) pts.emplace_back(lo + step * k(rng), lo + step * k(rng), lo + step * k(rng));
  return pts;
}

}  // namespace

TEST_CASE("box filter: an empty or flat box decides nothing; a point outside gets no epsilon") {
  BoxFilter f;
  CHECK(f.eps().orient == inf);
  CHECK(f.eps().insphere == inf);
  f.extend(KPoint(0, 0, 0));
  CHECK(f.eps().orient == inf);  // a single point: zero extent
  f.extend(KPoint(1, 1, 0));
  CHECK(f.eps().orient == inf);  // flat in z
  f.extend(KPoint(1, 1, 1));
  CHECK(f.eps().orient < 1e-13);
  CHECK(f.eps().insphere < 1e-11);
  CHECK(f.check());
  CHECK(f.eps_for(KPoint(0.5, 0.5, 0.5)).insphere == f.eps().insphere);
  CHECK(f.eps_for(KPoint(0.5, 0.5, 1.5)).insphere == inf);
  CHECK(f.eps_for(KPoint(0.5, -1e-300, 0.5)).orient == inf);
  // Beyond CGAL's overflow limits the filter is off.
  f.extend(KPoint(1e103, 1e103, 1e103));
  CHECK(f.eps().orient == inf);
  CHECK(f.eps().insphere == inf);
  f.clear();
  CHECK(f.eps().insphere == inf);
  CHECK_FALSE(f.contains(KPoint(0, 0, 0)));
}

TEST_CASE("box filter: the sign is CGAL's at every scale, uniform points") {
  std::mt19937_64 rng(7);
  Counts counts;
  const double extents[] = {1e-290, 1e-150, 1e-97, 1e-58, 1e-20, 1e-3, 1, 1e3, 1e20, 1e60, 1e61, 1e101, 1e150};
  const double offsets[] = {0, 1, -3e8, 1e15};
  for (double ext : extents)
    for (double off : offsets) {
      const double lo[3] = {off * ext, -off * ext, off};
      const double e[3] = {ext, ext, ext};
      check_against_cgal(uniform(rng, 64, lo, e), rng, counts);
    }
  // The filter must decide most tests where CGAL's semi-static bound would.
  INFO(counts.decided << " of " << counts.tests << " decided by the box");
  CHECK(counts.decided > counts.tests / 4);
  // The verdict alone decides most in-sphere tests that have a box.
  INFO(counts.undecided_spheres << " of " << counts.spheres_with_box << " in-sphere tests with a box undecided");
  CHECK(counts.spheres_with_box > 1000);
  CHECK(counts.undecided_spheres < counts.spheres_with_box / 4);
}

TEST_CASE("box filter: the sign is CGAL's for elongated boxes and tiny clusters in large boxes") {
  std::mt19937_64 rng(11);
  Counts counts;
  // Elongated: one axis long, two short.
  for (double longer : {1.0, 1e30, 1e60, 1e100})
    for (double shorter : {1e-97, 1e-58, 1e-30, 1e-10}) {
      const double lo[3] = {0, 0, 0};
      const double e[3] = {longer, shorter, shorter};
      check_against_cgal(uniform(rng, 64, lo, e), rng, counts);
    }
  // A cluster of tiny differences (products underflow) plus the corners of a
  // large box: the box's epsilon is large, the cluster's tests small.
  for (double spread : {1e-300, 1e-200, 1e-160, 1e-110, 1e-60})
    for (double big : {1.0, 1e10, 1e60}) {
      const double lo[3] = {0, 0, 0};
      const double e[3] = {spread, spread, spread};
      std::vector<KPoint> pts = uniform(rng, 64, lo, e);
      pts.emplace_back(big, big, big);
      pts.emplace_back(-big, 0, 0);
      check_against_cgal(pts, rng, counts);
      // Only the cluster's tests (the box still holds the far points).
      BoxFilter f;
      for (const KPoint& p : pts) f.extend(p);
      const FilterEps fe = f.eps();
      for (int g = 0; g < 300; ++g) {
        const KPoint& a = pts[rng() % 64];
        const KPoint& b = pts[rng() % 64];
        const KPoint& c = pts[rng() % 64];
        const KPoint& d = pts[rng() % 64];
        const KPoint& q = pts[rng() % 64];
        REQUIRE(pdt::detail::filtered_orient(a, b, c, d, fe.orient) == static_cast<int>(CGAL::orientation(a, b, c, d)));
        const int sp = static_cast<int>(CGAL::side_of_oriented_sphere(a, b, c, d, q));
        REQUIRE(pdt::detail::filtered_side_of_sphere(a, b, c, d, q, fe.insphere) == sp);
        const int v = pdt::detail::box_side_of_sphere(a, b, c, d, q, fe.insphere);
        REQUIRE((v == 0 || v == sp));
      }
    }
  SUCCEED(counts.tests << " tests");
}

TEST_CASE("box filter: tests inside a cluster, which the box cannot decide, get CGAL's semi-static bound") {
  // A cluster of extent s inside a box of extent 1: its determinants (s^3,
  // s^5) are far below the box's epsilon, so the box decides none of them and
  // CGAL's own bound, from the call's differences, decides with the same
  // determinant (predicates.hpp: orient_semi_static, side_of_sphere_semi_static).
  // Uniform points in the cluster, lattice ties in it, and one ulp off them,
  // where only interval or exact arithmetic decides.
  std::mt19937_64 rng(19);
  long nonzero = 0, zero = 0;
  for (double s : {1e-2, 1e-5, 1e-9, 1e-40, 1e-70})
    for (double at : {0.3, -7.0, 1e6}) {
      const double lo[3] = {at, 0.5 * at, -at};
      const double e[3] = {s, s, s};
      std::vector<std::vector<KPoint>> sets = {uniform(rng, 48, lo, e)};
      std::vector<KPoint> ties;
      for (const KPoint& p : lattice(rng, 48, 0, s / 3)) ties.emplace_back(at + p.x(), 0.5 * at + p.y(), -at + p.z());
      sets.push_back(ties);
      for (KPoint& p : ties)
        if (rng() % 2) p = KPoint(std::nextafter(p.x(), inf), p.y(), std::nextafter(p.z(), -inf));
      sets.push_back(ties);
      for (std::vector<KPoint>& pts : sets) {
        BoxFilter f;
        f.extend(KPoint(at - 0.5, 0.5 * at - 0.5, -at - 0.5));  // the box: extent 1 around the cluster
        f.extend(KPoint(at + 0.5, 0.5 * at + 0.5, -at + 0.5));
        for (const KPoint& p : pts) REQUIRE(f.contains(p));
        const FilterEps fe = f.eps();
        for (int g = 0; g < 600; ++g) {
          const KPoint& a = pts[rng() % pts.size()];
          const KPoint& b = pts[rng() % pts.size()];
          const KPoint& c = pts[rng() % pts.size()];
          const KPoint& d = pts[rng() % pts.size()];
          const KPoint& q = pts[rng() % pts.size()];
          INFO("cluster of extent " << s << " at " << at << ": " << a << " | " << b << " | " << c << " | " << d
                                    << " | " << q);
          const int o = static_cast<int>(CGAL::orientation(a, b, c, d));
          REQUIRE(pdt::detail::filtered_orient(a, b, c, d, fe.orient) == o);
          const int sp = static_cast<int>(CGAL::side_of_oriented_sphere(a, b, c, d, q));
          REQUIRE(pdt::detail::filtered_side_of_sphere(a, b, c, d, q, fe.insphere) == sp);
          const int v = pdt::detail::box_side_of_sphere(a, b, c, d, q, fe.insphere);
          REQUIRE((v == 0 || v == sp));
          (sp != 0 ? nonzero : zero) += 1;
        }
      }
    }
  // Both kinds occurred: signs the bound decides and exact ties it must not.
  CHECK(nonzero > 1000);
  CHECK(zero > 100);
}

TEST_CASE("box filter: the sign is CGAL's on exact ties (lattice points) and one ulp from them") {
  std::mt19937_64 rng(13);
  Counts counts;
  for (double step : {1e-100, 1e-3, 0.25, 1.0, 3e7, 1e50})
    for (double lo : {0.0, 1.0, -1e9, 1e15}) {
      std::vector<KPoint> pts = lattice(rng, 48, lo * step, step);
      check_against_cgal(pts, rng, counts, 1500);
      // One ulp off the lattice: the determinants are tiny but not zero.
      for (KPoint& p : pts)
        if (rng() % 2) p = KPoint(std::nextafter(p.x(), inf), p.y(), std::nextafter(p.z(), -inf));
      check_against_cgal(pts, rng, counts, 1500);
    }
  SUCCEED(counts.tests << " tests");
}

TEST_CASE("box filter: the perturbed in-sphere test is the same with and without it") {
  std::mt19937_64 rng(17);
  for (double step : {1e-3, 1.0, 1e40}) {
    const std::vector<KPoint> pts = lattice(rng, 64, 0.5 * step, step);
    BoxFilter f;
    for (const KPoint& p : pts) f.extend(p);
    for (int g = 0; g < 2000; ++g) {
      KPoint a = pts[rng() % pts.size()], b = pts[rng() % pts.size()], c = pts[rng() % pts.size()],
             d = pts[rng() % pts.size()];
      const KPoint& q = pts[rng() % pts.size()];
      const int o = static_cast<int>(CGAL::orientation(a, b, c, d));
      if (o == 0) continue;
      if (o < 0) std::swap(a, b);  // the perturbed test takes positively oriented cells
      REQUIRE(pdt::detail::perturbed_insphere(a, b, c, d, q, f.eps().insphere) ==
              pdt::detail::perturbed_insphere(a, b, c, d, q));
    }
  }
}

TEST_CASE("box filter: the triangulation's box holds every vertex and an engine's domain; a worker never grows it") {
  pdt::Triangulation t;
  for (const pdt::Point3& p : {pdt::Point3{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.2, 0.3, 0.1}}) t.insert(p);
  pdt::Triangulation::Impl& m = pdt::detail::impl_of(t);
  CHECK(m.filter.contains(KPoint(1, 1, 1)));
  CHECK_FALSE(m.filter.contains(KPoint(2, 0, 0)));
  CHECK(m.filter.eps().insphere < inf);
  // A locking context (an engine worker's) meeting a point outside the box
  // hands the insertion to a global step, holding nothing and changing nothing.
  pdt::detail::OpContext worker(m.new_context_id(), true);
  pdt::Triangulation::Impl::Inserted out;
  CHECK(m.insert(worker, pdt::detail::to_kpoint({2, 0, 0}), pdt::no_vertex, out) == pdt::detail::OpStatus::needs_global);
  CHECK(worker.held_shared.empty());
  CHECK(worker.held_exclusive.empty());
  // Also when it should insert only if a cell is alive (whose anchor it would hold).
  pdt::CellId live = 0;
  while (!t.is_cell(live) || !t.is_finite_cell(live)) ++live;
  const pdt::CellHandle h = m.handle_of(live);
  CHECK(m.insert(worker, pdt::detail::to_kpoint({2, 0, 0}), pdt::no_vertex, out, &h) ==
        pdt::detail::OpStatus::needs_global);
  CHECK(worker.held_shared.empty());
  CHECK(worker.held_exclusive.empty());
  CHECK_FALSE(m.filter.contains(KPoint(2, 0, 0)));
  CHECK(t.number_of_vertices() == 5);
  // Inside the box it inserts as usual.
  CHECK(m.insert(worker, pdt::detail::to_kpoint({0.5, 0.25, 0.125}), pdt::no_vertex, out) == pdt::detail::OpStatus::done);
  m.fold_counters(worker);
  CHECK(t.number_of_vertices() == 6);
  // An engine's domain joins the box when it attaches, before its workers run.
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, pdt::Box{{-3, -1, 0}, {4, 1, 2}});
    CHECK(m.filter.contains(KPoint(-3, -1, 0)));
    CHECK(m.filter.contains(KPoint(4, 1, 2)));
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> x(-3, 4), y(-1, 1), z(0, 2);
    for (int i = 0; i < 3000; ++i) e.insert({x(rng), y(rng), z(rng)}, [](const pdt::OpResult&) {});
    e.drain();
  });
  m.merge_pools(*m.seq, worker);
  std::string why;
  const bool valid = t.validate(&why);  // every vertex in the box, and Delaunay by CGAL's predicates alone
  INFO(why);
  CHECK(valid);
  CHECK(t.number_of_vertices() == 3006);
  t.clear();
  CHECK_FALSE(m.filter.contains(KPoint(0, 0, 0)));  // cleared with the vertices
}

TEST_CASE("box filter: the conflict search's quick verdict is in_conflict's answer or none, and none for infinite cells") {
  // Impl::quick_conflict, gather_conflict_zone's first pass: for every live
  // cell and points inside, on and near the hull, a nonzero verdict must be
  // in_conflict's answer, and an infinite cell must get none (its test is
  // the hull facet's, not a sphere's).
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(0, 1);
  pdt::Triangulation t;
  for (int i = 0; i < 300; ++i) t.insert({u(rng), u(rng), u(rng)});
  for (int i = 0; i < 40; ++i) t.insert({0.25 * (i % 5), 0.25 * ((i / 5) % 5), 0.0});  // lattice ties on the hull
  pdt::Triangulation::Impl& m = pdt::detail::impl_of(t);
  const FilterEps e = m.filter.eps();
  REQUIRE(e.insphere < inf);
  std::vector<KPoint> probes;
  for (int i = 0; i < 60; ++i) probes.emplace_back(u(rng), u(rng), u(rng));
  for (int i = 0; i < 20; ++i) probes.emplace_back(0.25 * (i % 5), 0.25 * (i / 5), 0.0);
  long infinite = 0, decided = 0, asked = 0;
  for (pdt::CellId c = 0; c < m.cells.size(); ++c) {
    if (!t.is_cell(c)) continue;
    for (const KPoint& p : probes) {
      const int v = m.quick_conflict(c, p, e);
      ++asked;
      if (!t.is_finite_cell(c)) {
        REQUIRE(v == 0);
        ++infinite;
        continue;
      }
      if (v != 0) {
        ++decided;
        REQUIRE((v > 0) == m.in_conflict(c, p, e));
      }
    }
  }
  CHECK(infinite > 0);
  CHECK(decided > asked / 2);
}
