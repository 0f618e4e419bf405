// SPDX-License-Identifier: MIT
// `pdt refine`, judged from the outside: it is run as a process, and its
// output is checked independently. The mesh (.node/.ele) must be the Delaunay
// triangulation of its points (CGAL's); every tetrahedron whose circumcentre
// is inside the domain, out of the protected layer along the surface, must
// meet both bounds (circumcentres computed here, with CGAL's kernel); the
// trace must replay, sequentially and on the engine, to the same
// triangulation; and this with 1, 2 and 8 workers. Bad arguments are refused.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/io_test_util.hpp"
#include "common/tool_run.hpp"
#include "pdt/io.hpp"
#include "refine/domain.hpp"
#include "refine/quality.hpp"
#include "refine/refiner.hpp"
#include "refine/samples.hpp"

using namespace pdt_test;
using pdt::Point3;

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

// The torus, written here again: inside where < 0 (the tool's is not used to judge).
double torus(const Point3& p) {
  const double r = std::sqrt(p.x * p.x + p.y * p.y) - 1;
  return std::sqrt(r * r + p.z * p.z) - 0.4;
}

// Tetrahedra as sorted point triples-of-coordinates, to compare meshes whose
// node numbers differ.
std::vector<std::array<Point3, 4>> tets_of(const pdt::Mesh& m) {
  std::vector<std::array<Point3, 4>> out;
  auto less = [](const Point3& a, const Point3& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); };
  for (const auto& t : m.tets) {
    std::array<Point3, 4> q{m.points[t[0]], m.points[t[1]], m.points[t[2]], m.points[t[3]]};
    std::sort(q.begin(), q.end(), less);
    out.push_back(q);
  }
  std::sort(out.begin(), out.end(), [&](const auto& a, const auto& b) {
    return std::lexicographical_compare(a.begin(), a.end(), b.begin(), b.end(), less);
  });
  return out;
}

}  // namespace

TEST_CASE("refine: a torus, with 1, 2 and 8 workers: Delaunay, within its bounds, and its trace replays",
          "[refine][cli]") {
  if (!have_tool()) return;
  const double size = 0.12, ratio = 2;
  // The surface samples the refiner protects the surface with (same size and seed).
  const std::vector<Point3> samples = pdt_refine::surface_samples(pdt_refine::domain_by_name("torus"), size, 1);
  REQUIRE(samples.size() > 100);
  for (const char* workers : {"1", "2", "8"}) {
    INFO(workers << " workers");
    TempDir d;
    const std::string mesh = d.file("torus.node"), trace = d.file("torus.ops");
    Result r = run_pdt(d, std::string("refine --domain torus --size 0.12 --threads ") + workers + " --out '" + mesh +
                              "' --trace '" + trace + "' --validate");
    INFO("stdout:\n" << r.out << "\nstderr:\n" << r.err);
    REQUIRE(r.code == 0);
    CHECK(r.out.find("validate         ok") != std::string::npos);
    CHECK(r.out.find("bounds           met") != std::string::npos);
    CHECK(r.out.find("wrote            " + mesh + " and " + d.file("torus.ele")) != std::string::npos);
    const pdt::Mesh m = pdt::read_tetgen(mesh);
    REQUIRE(m.points.size() > 500);

    // Delaunay: CGAL's triangulation of the same points.
    {
      const TetList want = cgal_tets(m.points);
      TetList got;
      for (const auto& t : m.tets) got.push_back({t[0], t[1], t[2], t[3]});
      canonicalize(got);
      REQUIRE(got.size() == want.size());
      REQUIRE((got == want));
    }
    // The bounds, for every tetrahedron whose circumcentre is inside and not
    // within a quarter of the size of a surface sample (the protected layer).
    std::size_t judged = 0, bad = 0, unplaced = 0;
    for (const auto& t : m.tets) {
      const K::Point_3 p[4] = {to_cgal(m.points[t[0]]), to_cgal(m.points[t[1]]), to_cgal(m.points[t[2]]),
                               to_cgal(m.points[t[3]])};
      const K::Point_3 c = CGAL::circumcenter(p[0], p[1], p[2], p[3]);
      const Point3 cc{c.x(), c.y(), c.z()};
      // A tetrahedron so nearly flat that doubles cannot place its centre
      // (not equidistant from its vertices to 1e-6) is not judged, by the
      // refiner either (TetShape::ok); there are few.
      const double r2 = CGAL::squared_distance(c, p[0]);
      bool placed = std::isfinite(r2) && r2 > 0;
      for (int i = 1; i < 4 && placed; ++i) placed = std::fabs(CGAL::squared_distance(c, p[i]) - r2) <= pdt_refine::placed_tolerance * r2;
      if (!placed) {
        ++unplaced;
        continue;
      }
      if (!(torus(cc) < 0)) continue;
      bool in_layer = false;
      for (const Point3& s : samples)
        if ((s.x - cc.x) * (s.x - cc.x) + (s.y - cc.y) * (s.y - cc.y) + (s.z - cc.z) * (s.z - cc.z) <
            0.25 * size * 0.25 * size) {
          in_layer = true;
          break;
        }
      if (in_layer) continue;
      ++judged;
      const double radius = std::sqrt(CGAL::squared_distance(c, p[0]));
      double shortest = HUGE_VAL;
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) shortest = std::min(shortest, std::sqrt(CGAL::squared_distance(p[i], p[j])));
      // 1e-9 of slack: the refiner judges with its own (double) circumcentre.
      if (radius > size * (1 + 1e-9) || radius / shortest > ratio * (1 + 1e-9)) ++bad;
    }
    CHECK(judged > m.tets.size() / 2);
    CHECK(bad == 0);
    CHECK(unplaced < m.tets.size() / 100);
    // The slivers it reports (inside: centroid inside; dihedral angle under
    // 5 degrees), counted here with CGAL's dihedral angles. 1 of slack: a
    // centroid or angle on the line may round either way.
    {
      std::size_t slivers = 0;
      static constexpr int edge[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
      for (const auto& t : m.tets) {
        const K::Point_3 p[4] = {to_cgal(m.points[t[0]]), to_cgal(m.points[t[1]]), to_cgal(m.points[t[2]]),
                                 to_cgal(m.points[t[3]])};
        const K::Point_3 g = CGAL::centroid(p[0], p[1], p[2], p[3]);
        if (!(torus({g.x(), g.y(), g.z()}) < 0)) continue;
        double smallest = 180;
        for (const auto& e : edge)
          smallest = std::min(smallest, std::abs(CGAL::approximate_dihedral_angle(p[e[0]], p[e[1]], p[e[2]], p[e[3]])));
        if (smallest < 5) ++slivers;
      }
      const std::size_t at = r.out.find(" slivers under 5 degrees inside");
      REQUIRE(at != std::string::npos);
      const std::size_t start = r.out.rfind(' ', at - 1) + 1;
      std::string printed = r.out.substr(start, at - start);
      printed.erase(std::remove(printed.begin(), printed.end(), ','), printed.end());
      const long reported = std::stol(printed);
      CHECK(std::abs(reported - static_cast<long>(slivers)) <= 1);
    }
    // The trace replays to the same triangulation, sequentially and on the engine.
    for (const char* replay : {"", " --threads 3"}) {
      INFO("replay" << replay);
      const std::string again = d.file("again.node");
      r = run_pdt(d, "run '" + trace + "'" + replay + " --out '" + again + "'");
      REQUIRE(r.code == 0);
      CHECK(r.out.find("removals         0\n") == std::string::npos);  // the stream does mix in removals
      CHECK((tets_of(pdt::read_tetgen(again)) == tets_of(m)));
    }
  }
}

TEST_CASE("refine: the pruned surface sampling gives exactly the brute-force scan's samples", "[refine]") {
  // Without a Lipschitz or outside bound, or `uncrossed`, surface_samples visits every cell:
  // the pruned scan must give the same points in the same order.
  for (const char* name : {"sphere", "torus", "gyroid"})
    for (double size : {0.3, 0.11})
      for (std::uint64_t seed : {1u, 7u}) {
        INFO(name << " size " << size << " seed " << seed);
        const pdt_refine::Domain d = pdt_refine::domain_by_name(name);
        pdt_refine::Domain brute = d;
        brute.lipschitz = 0;
        brute.outside_bound = nullptr;
        brute.uncrossed = nullptr;
        const std::vector<Point3> pruned = pdt_refine::surface_samples(d, size, seed);
        const std::vector<Point3> all = pdt_refine::surface_samples(brute, size, seed);
        REQUIRE(pruned.size() > 10);
        REQUIRE(pruned.size() == all.size());
        for (std::size_t i = 0; i < all.size(); ++i) REQUIRE(same_bits(pruned[i], all[i]));
      }
}

TEST_CASE("refine: every domain, a .vtu with the quality fields", "[refine][cli]") {
  if (!have_tool()) return;
  for (const char* domain : {"sphere", "gyroid"}) {
    INFO(domain);
    TempDir d;
    const Result r = run_pdt(d, std::string("refine --domain ") + domain + " --size 0.15 --threads 2 --out '" +
                                    d.file("m.vtu") + "'");
    INFO("stdout:\n" << r.out << "\nstderr:\n" << r.err);
    REQUIRE(r.code == 0);
    const std::string vtu = read_file(d.file("m.vtu"));
    for (const char* field : {"radius_edge_ratio", "min_dihedral_angle", "domain_label", "vtkZLibDataCompressor"})
      CHECK(vtu.find(field) != std::string::npos);
  }
}

TEST_CASE("refine: bad arguments are refused, naming the rule", "[refine][cli]") {
  if (!have_tool()) return;
  TempDir d;
  struct Case {
    const char* args;
    const char* says;
  };
  for (const Case& c : {Case{"refine --domain cube --size 0.1", "unknown domain 'cube'"},
                        Case{"refine --domain torus --size 0", "expected a positive number"},
                        Case{"refine --domain torus --size -1", "expected a positive number"},
                        Case{"refine --domain torus --size 0.1 --ratio 1.5", "at least 2"},
                        Case{"refine --domain sphere --size 100", "leaves the sphere domain without surface samples"},
                        Case{"refine --domain torus", "needs --size"},
                        Case{"refine --size 0.1", "needs --domain"},
                        Case{"refine --domain torus --size 0.1 --out mesh.stl", "expected a name ending in .vtu"}}) {
    INFO(c.args);
    const Result r = run_pdt(d, c.args);
    CHECK(r.code == 2);
    CHECK(r.err.find(c.says) != std::string::npos);
  }
}

TEST_CASE("refine: a point budget stops it, and says so", "[refine][cli]") {
  if (!have_tool()) return;
  TempDir d;
  const Result r = run_pdt(d, "refine --domain sphere --size 0.05 --threads 2 --budget 10000");
  INFO("stdout:\n" << r.out);
  CHECK(r.code == 1);  // the bounds are missed
  CHECK(r.out.find("the point budget of 10,000 was hit") != std::string::npos);
  {
    const std::size_t at = r.out.find("insertions");
    REQUIRE(at != std::string::npos);
    CHECK(std::stoul(r.out.substr(r.out.find_first_of("0123456789", at))) <= 10000);
  }
  // The surface samples (512 on the torus at 0.2) go in before the end: a
  // budget below them and the corners stops it before anything is inserted,
  // saying why.
  for (const char* budget : {"500", "300", "100", "12", "5"}) {
    const Result small = run_pdt(d, std::string("refine --domain torus --size 0.2 --threads 2 --budget ") + budget);
    INFO("stdout:\n" << small.out);
    CHECK(small.code == 1);
    // Far below 512 a coarser look (at 0.8: 4 times the spacing) already
    // estimates over twice the budget and says "more"; close to it, the
    // sampling runs through and gives the count.
    const std::string says =
        std::stoul(budget) >= 300
            ? "the surface needs 512 sample points; with the box's 8 corners that is 520, over the point budget of "
            : "the surface needs more sample points than fit the point budget of ";
    CHECK(small.out.find(says + budget + " (") != std::string::npos);
    CHECK(small.out.find("insertions") == std::string::npos);  // refused before anything was inserted
  }
  // Samples that fit, but not with the corners: refused, counting them.
  const Result corners = run_pdt(d, "refine --domain torus --size 0.2 --threads 2 --budget 515");
  CHECK(corners.code == 1);
  CHECK(corners.out.find("512 sample points; with the box's 8 corners that is 520, over the point budget of 515") !=
        std::string::npos);
  // Samples that fit, but not with the starting points (17): stopped before
  // the samples go in, below the budget, saying what the step needed.
  const Result samples = run_pdt(d, "refine --domain torus --size 0.2 --threads 2 --budget 528");
  INFO("stdout:\n" << samples.out);
  CHECK(samples.code == 1);
  CHECK(samples.out.find("the point budget of 528 stopped it: ") != std::string::npos);
  CHECK(samples.out.find("its next step needs 512 more") != std::string::npos);
  // Refined as far as the interior asked, the surface samples left (all at
  // once) do not fit: stopped there, below the budget, saying so.
  const Result rest = run_pdt(d, "refine --domain sphere --size 0.2 --threads 2 --budget 700");
  INFO("stdout:\n" << rest.out);
  CHECK(rest.code == 1);
  CHECK(rest.out.find("the point budget of 700 stopped it: ") != std::string::npos);
  CHECK(rest.out.find(" was hit") == std::string::npos);
  // A size beyond any coarser look (4 times it overflows to infinity):
  // refused at once: no sample.
  const Result huge = run_pdt(d, "refine --domain sphere --size 1e308 --threads 1");
  CHECK(huge.code == 2);
  CHECK(huge.err.find("leaves the sphere domain without surface samples") != std::string::npos);
  // A size whose surface needs millions of samples, under a small budget:
  // the sampling stops early (it took minutes and gigabytes before).
  const Result tiny = run_pdt(d, "refine --domain gyroid --size 1e-3 --threads 2 --budget 100");
  INFO("stdout:\n" << tiny.out);
  CHECK(tiny.code == 1);
  CHECK(tiny.out.find("the surface needs more sample points than fit the point budget of 100") != std::string::npos);
}

TEST_CASE("refine: the surface samples' index finds the nearest sample within a radius, as a scan does", "[refine]") {
  // Samples on a grid of cells of side 0.05 (as the refiner's: half its
  // size), with duplicates, -0.0, negative coordinates, and clusters several
  // to a cell; queries anywhere, radii from a tenth of a cell to four cells.
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Point3> pts;
  for (int i = 0; i < 3000; ++i) pts.push_back({u(rng), u(rng), 0.3 * u(rng)});
  for (int i = 0; i < 200; ++i) pts.push_back({0.5 + 1e-3 * u(rng), -0.25 + 1e-3 * u(rng), 1e-3 * u(rng)});
  pts.push_back(pts[7]);  // a duplicate
  pts.push_back({-0.0, 0.0, -0.0});
  const double cell = 0.05;
  pdt_refine::Samples s(pts, cell);
  REQUIRE(s.check());
  REQUIRE(s.size() == pts.size());
  for (std::uint32_t i = 0; i < pts.size(); i += 3) REQUIRE(s.claim(i));  // every third taken
  REQUIRE_FALSE(s.claim(0));
  for (int q = 0; q < 4000; ++q) {
    const Point3 p{1.1 * u(rng), 1.1 * u(rng), 0.4 * u(rng)};
    const double r = cell * (q % 4 == 0 ? 0.1 : q % 4 == 1 ? 0.5 : q % 4 == 2 ? 1.3 : 4.0);
    double best = r * r, best_free = r * r;
    bool any = false, any_free = false;
    for (std::uint32_t i = 0; i < pts.size(); ++i) {
      const double d2 = pdt_refine::dist2(p, pts[i]);
      if (d2 < best) best = d2, any = true;
      if (i % 3 != 0 && d2 < best_free) best_free = d2, any_free = true;
    }
    INFO("query " << p.x << " " << p.y << " " << p.z << ", radius " << r);
    const std::int64_t got = s.nearest_within(p, r);
    REQUIRE((got >= 0) == any);
    if (any) REQUIRE(pdt_refine::dist2(p, pts[static_cast<std::size_t>(got)]) == best);
    const std::int64_t got_free = s.nearest_free_within(p, r);
    REQUIRE((got_free >= 0) == any_free);
    if (any_free) {
      REQUIRE(got_free % 3 != 0);
      REQUIRE(pdt_refine::dist2(p, pts[static_cast<std::size_t>(got_free)]) == best_free);
    }
  }
  for (const Point3& p : pts) REQUIRE(s.is_sample(p));
  REQUIRE(s.is_sample({0.0, -0.0, 0.0}));  // equal to the -0.0 sample
  REQUIRE_FALSE(s.is_sample({std::nextafter(pts[5].x, 2.0), pts[5].y, pts[5].z}));
  REQUIRE_FALSE(s.is_sample({0.5, 0.5, 0.5}));
  // No samples: nothing near, nothing is one.
  pdt_refine::Samples none({}, cell);
  REQUIRE(none.check());
  REQUIRE(none.nearest_within({0, 0, 0}, 1) == -1);
  REQUIRE_FALSE(none.is_sample({0, 0, 0}));
}

TEST_CASE("refine: a tetrahedron too flat for doubles to place its circumcentre is not judged", "[refine]") {
  using pdt_refine::shape;
  // Four torus surface samples found in a refined mesh: two pairs mirrored
  // (to the last bits) across the plane z = 0, so nearly coplanar and nearly
  // cocircular. The centre doubles give is 0.159-0.179 from the vertices.
  const std::array<Point3, 4> flat = {Point3{0.32430716030113821, -0.50962553761607376, -0.056874320274814608},
                                      Point3{0.24958657943168427, -0.549090474750208, -0.050126194486461266},
                                      Point3{0.32430716030113826, -0.50962553761607376, 0.056874320274814628},
                                      Point3{0.24958657943168427, -0.549090474750208, 0.050126194486461294}};
  CHECK_FALSE(shape(flat).ok);
  // A regular tetrahedron and a thin sliver (one vertex 1e-4 off the plane of
  // a square's three others) are placed: centre equidistant, radius right.
  const std::array<Point3, 4> regular = {Point3{1, 1, 1}, Point3{1, -1, -1}, Point3{-1, 1, -1}, Point3{-1, -1, 1}};
  const pdt_refine::TetShape r = shape(regular);
  REQUIRE(r.ok);
  CHECK(std::fabs(r.circumradius - std::sqrt(3.0)) < 1e-12);
  CHECK(std::fabs(r.circumcentre.x) + std::fabs(r.circumcentre.y) + std::fabs(r.circumcentre.z) < 1e-12);
  const std::array<Point3, 4> sliver = {Point3{0, 0, 0}, Point3{1, 0, 0}, Point3{0, 1, 0}, Point3{1, 1, 1e-4}};
  const pdt_refine::TetShape s = shape(sliver);
  REQUIRE(s.ok);
  for (const Point3& v : sliver)
    CHECK(std::fabs(std::sqrt(pdt_refine::dist2(v, s.circumcentre)) - s.circumradius) < 1e-9 * s.circumradius);
  // Exactly flat: no circumsphere.
  CHECK_FALSE(shape({Point3{0, 0, 0}, Point3{1, 0, 0}, Point3{0, 1, 0}, Point3{1, 1, 0}}).ok);
}

TEST_CASE("refine: the quality measure gives the same figures on one thread and on several", "[refine]") {
  // measure() splits the cells among threads when asked; its counts, minima
  // and maxima must not depend on the split.
  pdt_refine::RefineOptions o;
  o.domain = pdt_refine::domain_by_name("torus");
  o.size = 0.1;
  o.workers = 2;
  pdt::Triangulation t;
  const pdt_refine::RefineStats st = pdt_refine::refine(t, o);
  REQUIRE_FALSE(st.budget_hit);
  const pdt_refine::MeshQuality one = pdt_refine::measure(t, o.domain, o.size, o.ratio, o.seed, 1);
  REQUIRE(one.inside > 1000);
  REQUIRE(one.judged > one.inside / 2);
  CHECK(one.violations == 0);
  CHECK(one.worst_ratio <= o.ratio);
  for (unsigned threads : {2u, 4u, 7u}) {
    INFO(threads << " threads");
    const pdt_refine::MeshQuality q = pdt_refine::measure(t, o.domain, o.size, o.ratio, o.seed, threads);
    CHECK(q.inside == one.inside);
    CHECK(q.judged == one.judged);
    CHECK(q.protected_layer == one.protected_layer);
    CHECK(q.unplaced == one.unplaced);
    CHECK(q.violations == one.violations);
    CHECK(q.worst_ratio == one.worst_ratio);
    CHECK(q.largest_radius == one.largest_radius);
    CHECK(q.min_dihedral == one.min_dihedral);
    CHECK(q.min_dihedral_judged == one.min_dihedral_judged);
    CHECK(q.slivers == one.slivers);
    CHECK(q.slivers_judged == one.slivers_judged);
  }
}
