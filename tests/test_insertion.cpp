// SPDX-License-Identifier: MIT
// Insertion: pdt::Triangulation equals CGAL's Delaunay_triangulation_3 of the
// same points, whatever the insertion order, on synthetic, degenerate and real
// point sets; bad input is rejected without changing anything; locate(),
// nearest_vertex() and hints behave.
#include <oneapi/tbb/task_arena.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/point_sets.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"
#include "triangulation_impl.hpp"  // the jump-grid test reads the grid

using namespace pdt_test;
using pdt::Point3;

namespace {

// Builds a triangulation of `order` (inserted in that order), checks it
// against the reference computed for `pts` (same points, any order) and
// returns its canonical form (indices into pts).
TetList build_and_check(const std::vector<Point3>& pts, const std::vector<Point3>& order, const CgalResult& ref) {
  pdt::Triangulation t;
  insert_all(t, order);
  require_valid(t);
  TetList got = canonical_tets(t, pts);
  const bool same = got == ref.tets;
  std::string mismatch = same ? std::string() : describe_mismatch(got, ref.tets, pts);
  INFO(mismatch);
  REQUIRE(same);
  REQUIRE(t.dimension() == ref.dimension);
  REQUIRE(t.number_of_vertices() == ref.vertices);
  REQUIRE(t.number_of_finite_cells() == ref.tets.size());
  if (ref.dimension == 3) REQUIRE(t.number_of_cells() == ref.cells);
  std::string why;
  const bool oriented = all_positively_oriented(t, &why);
  INFO(why);
  REQUIRE(oriented);
  return got;
}

// The reference, then pdt with the given order and `orders` more shuffles;
// all give the same canonical tetrahedra.
void check_orders(const std::vector<Point3>& pts, int orders, std::uint64_t seed) {
  const CgalResult ref = cgal_reference(pts);
  std::vector<Point3> order = pts;
  TetList first;
  for (int k = 0; k <= orders; ++k) {
    INFO("order " << k << " (0 = as given), seed " << seed);
    if (k > 0) shuffle(order, seed * 1000 + k);
    TetList got = build_and_check(pts, order, ref);
    if (k == 0)
      first = std::move(got);
    else
      REQUIRE((got == first));
  }
}

std::vector<Point3> read_or_empty(const std::string& rel, std::size_t max_points = 0) {
  const std::string path = shared_data(rel);
  if (!std::filesystem::exists(path)) {
    WARN("data file absent, skipped: " << path);
    return {};
  }
  std::vector<Point3> pts = pdt::read_points(path);
  if (max_points && pts.size() > max_points) pts.resize(max_points);
  return pts;
}

const pdt::Distribution all_dists[] = {pdt::Distribution::uniform, pdt::Distribution::normal, pdt::Distribution::line,
                                       pdt::Distribution::grid, pdt::Distribution::sphere};

}  // namespace

TEST_CASE("insertion equals CGAL for every distribution and order", "[insert]") {
  for (pdt::Distribution d : all_dists) {
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
      INFO("distribution " << pdt::to_string(d) << ", seed " << seed);
      std::vector<Point3> pts = generated_points(d, 3000, seed);
      REQUIRE(pts.size() == 3000);
      check_orders(pts, 2, seed);
    }
  }
}

TEST_CASE("insertion of an integer lattice", "[insert][degenerate]") {
  std::vector<Point3> pts = lattice(6);
  SECTION("lexicographic order") { check_orders(pts, 0, 1); }
  SECTION("shuffled") {
    shuffle(pts, 7);
    check_orders(pts, 3, 7);
  }
  SECTION("reverse lexicographic order") {
    std::reverse(pts.begin(), pts.end());
    check_orders(pts, 0, 1);
  }
}

TEST_CASE("insertion of exactly cospherical points", "[insert][degenerate]") {
  for (int r2 : {50, 325, 2025}) {
    std::vector<Point3> pts = cospherical(r2);
    INFO("R^2 = " << r2 << ", " << pts.size() << " points");
    REQUIRE(pts.size() >= 30);
    check_orders(pts, 3, r2);
    // With the centre added every point is a neighbour of it.
    pts.push_back({0, 0, 0});
    check_orders(pts, 1, r2 + 1);
  }
}

TEST_CASE("cavities larger than the cone's edge table", "[insert][degenerate]") {
  // The cone over a cavity boundary of at most 63 finite vertices is linked
  // through a directed-edge table, larger ones through a hash map. The centre
  // of exactly cospherical points has them all on its cavity's boundary.
  std::vector<Point3> pts = cospherical(2025);
  REQUIRE(pts.size() > 64);
  pdt::Triangulation t;
  insert_all(t, pts);
  const std::uint64_t before = t.stats().cells_created_by_insert;
  t.insert({0, 0, 0});
  // A triangulated sphere with k vertices has 2k - 4 triangles: one new cell each.
  REQUIRE(t.stats().cells_created_by_insert - before >= 2 * pts.size() - 4);
  pts.push_back({0, 0, 0});
  require_valid(t);
  require_same_as_cgal(t, pts);
  // and an ordinary insertion next to it, back on the table
  t.insert({1, 2, 3});
  pts.push_back({1, 2, 3});
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("coplanar start, then points off the plane", "[insert][degenerate]") {
  std::vector<Point3> plane;
  for (int x = 0; x < 20; ++x)
    for (int y = 0; y < 20; ++y) plane.push_back({double(x), double(y), 0});
  shuffle(plane, 3);
  pdt::Triangulation t;
  for (const auto& p : plane) REQUIRE(t.insert(p).inserted);
  REQUIRE(t.dimension() == 2);
  REQUIRE(t.number_of_vertices() == 400);
  REQUIRE(t.number_of_finite_cells() == 0);
  REQUIRE(t.finite_cells().empty());
  require_valid(t);

  std::vector<Point3> all = plane;
  std::mt19937_64 rng(11);
  for (int k = 0; k < 100; ++k) {
    Point3 p{uniform(rng, -1, 20), uniform(rng, -1, 20), uniform(rng, -3, 3)};
    if (k == 0) p.z = 1.5;  // the first one surely off the plane
    all.push_back(p);
    t.insert(p);
    if (k == 0) {
      REQUIRE(t.dimension() == 3);
      require_same_as_cgal(t, all);
    }
  }
  require_valid(t);
  require_same_as_cgal(t, all);
  // Also with integer points above and below (many cospherical with the grid).
  for (int x = 0; x < 20; x += 3)
    for (int y = 0; y < 20; y += 4) {
      all.push_back({double(x), double(y), double((x + y) % 3) - 1});
      t.insert(all.back());
    }
  require_valid(t);
  require_same_as_cgal(t, all);
}

TEST_CASE("collinear start, then a plane, then space", "[insert][degenerate]") {
  pdt::Triangulation t;
  std::vector<Point3> all;
  for (int i = 0; i < 50; ++i) all.push_back({double((i * 37) % 50), double((i * 37) % 50) * 2, 0});
  for (const auto& p : all) t.insert(p);
  REQUIRE(t.dimension() == 1);
  REQUIRE(t.number_of_vertices() == 50);
  REQUIRE(t.number_of_finite_cells() == 0);
  require_valid(t);
  all.push_back({0, 0, 0.0});  // duplicate of a point already on the line
  REQUIRE_FALSE(t.insert(all.back()).inserted);
  REQUIRE(t.dimension() == 1);
  all.push_back({5, 0, 0});  // off the line, in the plane z = 0
  t.insert(all.back());
  REQUIRE(t.dimension() == 2);
  REQUIRE(t.number_of_finite_cells() == 0);
  for (int i = 0; i < 10; ++i) {
    all.push_back({double(i), double(3 * i % 7), 0});
    t.insert(all.back());
  }
  REQUIRE(t.dimension() == 2);
  all.push_back({1, 2, 3});
  t.insert(all.back());
  REQUIRE(t.dimension() == 3);
  require_valid(t);
  require_same_as_cgal(t, all);
  for (int i = 0; i < 40; ++i) {
    all.push_back({double(i % 5), double(i % 7), double(i % 3) - 1});
    t.insert(all.back());
  }
  require_valid(t);
  require_same_as_cgal(t, all);
}

TEST_CASE("points coplanar forever", "[insert][degenerate]") {
  // The plane x + 2y - z = 3, with integer and with dyadic coordinates: exact.
  pdt::Triangulation t;
  std::vector<Point3> pts;
  std::mt19937_64 rng(5);
  for (int k = 0; k < 300; ++k) {
    double x = double(rng() % 1000) / 8, y = double(rng() % 1000) / 16;
    pts.push_back({x, y, x + 2 * y - 3});
  }
  std::size_t distinct = make_point_index(pts).size();
  for (const auto& p : pts) t.insert(p);
  REQUIRE(t.dimension() == 2);
  REQUIRE(t.number_of_vertices() == distinct);
  REQUIRE(t.number_of_finite_cells() == 0);
  REQUIRE(t.finite_cells().empty());
  REQUIRE(t.locate({1, 1, 1}).kind == pdt::LocateKind::none);
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("coplanar points go in in amortised constant time: the flat list grows geometrically", "[insert][degenerate]") {
  // The flat list was reserved one more element per insertion, which copies
  // it whole each time: 400k coplanar points took 7.5 s, 1M would take about
  // a minute. Its capacity now doubles: after 1000 insertions it is past
  // 1000, and it was reallocated about log2(n) times, not n.
  pdt::Triangulation t;
  const auto& m = pdt::detail::impl_of(t);
  std::mt19937_64 rng(11);
  std::size_t reallocations = 0;
  const void* storage = nullptr;
  for (int k = 0; k < 20000; ++k) {
    t.insert({double(rng() % 100000) / 64, double(rng() % 100000) / 64, 0});
    if (m.flat.data() != storage) {
      ++reallocations;
      storage = m.flat.data();
    }
  }
  REQUIRE(t.dimension() == 2);
  CHECK(m.flat.size() == t.number_of_vertices());
  CHECK(reallocations <= 20);
  CHECK(m.flat.capacity() >= m.flat.size());
  require_valid(t);
}

TEST_CASE("the flat index clears in time proportional to what it holds", "[insert][degenerate]") {
  // A removal's scratch triangulation is cleared for every removal: once a
  // large coplanar link had grown its table, every later removal cleared
  // that table twice (memset 38% of a profile, removals twice as slow).
  pdt::detail::StableArray<pdt::detail::VertexRec> verts(1 << 16);
  pdt::detail::FlatIndex index;
  const std::size_t n = 20000;
  verts.grow(n + 1);
  index.reserve(n, verts);
  for (pdt::VertexId v = 1; v <= n; ++v) {
    verts[v].p = pdt::detail::KPoint(double(v), 0.5, 0);
    index.insert(v, verts);
  }
  REQUIRE(index.size() == n);
  REQUIRE(index.find(verts[77].p, verts) == 77);
  index.clear();
  CHECK(index.size() == 0);
  CHECK(index.table_size() <= 1024);  // given back, not swept
  CHECK(index.find(verts[77].p, verts) == pdt::no_vertex);
  index.reserve(3, verts);
  index.insert(5, verts);
  CHECK(index.find(verts[5].p, verts) == 5);
  CHECK(index.table_size() <= 1024);
  index.clear();
  CHECK(index.find(verts[5].p, verts) == pdt::no_vertex);
}

TEST_CASE("fewer than 4 points and the first tetrahedron", "[insert]") {
  pdt::Triangulation t;
  REQUIRE(t.dimension() == -1);
  REQUIRE(t.number_of_vertices() == 0);
  REQUIRE(t.number_of_finite_cells() == 0);
  REQUIRE(t.vertices().empty());
  REQUIRE(t.nearest_vertex({0, 0, 0}) == pdt::no_vertex);
  require_valid(t);

  auto a = t.insert({0, 0, 0});
  REQUIRE(a.inserted);
  REQUIRE(a.vertex != pdt::infinite_vertex);
  REQUIRE(t.is_vertex(a.vertex));
  REQUIRE(t.point(a.vertex) == Point3{0, 0, 0});
  REQUIRE(t.dimension() == 0);
  REQUIRE(t.number_of_vertices() == 1);
  require_valid(t);

  auto b = t.insert({1, 0, 0});
  REQUIRE(b.inserted);
  REQUIRE(b.vertex != a.vertex);
  REQUIRE(t.dimension() == 1);
  auto c = t.insert({2, 0, 0});  // collinear
  REQUIRE(t.dimension() == 1);
  auto d = t.insert({0, 1, 0});
  REQUIRE(t.dimension() == 2);
  REQUIRE(t.number_of_finite_cells() == 0);
  require_valid(t);
  auto e = t.insert({0, 0, 1});
  REQUIRE(t.dimension() == 3);
  // 5 points, 4 of them (a, c, d, e) spanning the hull and b on edge ac: 2 tets.
  REQUIRE(t.number_of_vertices() == 5);
  REQUIRE(t.number_of_finite_cells() == 2);
  require_valid(t);
  require_same_as_cgal(t);
  const std::set<pdt::VertexId> ids{a.vertex, b.vertex, c.vertex, d.vertex, e.vertex};
  REQUIRE(ids.size() == 5);
  REQUIRE(std::vector<pdt::VertexId>(ids.begin(), ids.end()) == t.vertices());

  SECTION("exactly 4 points: one tetrahedron, four infinite cells") {
    pdt::Triangulation u;
    u.insert({0, 0, 0});
    u.insert({1, 0, 0});
    u.insert({0, 1, 0});
    REQUIRE(u.dimension() == 2);
    u.insert({0, 0, 1});
    REQUIRE(u.dimension() == 3);
    REQUIRE(u.number_of_finite_cells() == 1);
    REQUIRE(u.number_of_cells() == 5);
    require_valid(u);
    require_same_as_cgal(u);
  }
  SECTION("clear empties") {
    t.clear();
    REQUIRE(t.dimension() == -1);
    REQUIRE(t.number_of_vertices() == 0);
    REQUIRE(t.number_of_cells() == 0);
    REQUIRE(t.vertices().empty());
    require_valid(t);
    insert_all(t, random_points(100, 3));
    require_valid(t);
    require_same_as_cgal(t);
  }
}

TEST_CASE("duplicates raise the multiplicity", "[insert]") {
  std::vector<Point3> pts = random_points(500, 21);
  pdt::Triangulation t;
  std::vector<pdt::VertexId> ids = insert_all(t, pts);
  const TetList before = canonical_tets(t, pts);
  const auto stats_before = t.stats();
  for (std::size_t i = 0; i < pts.size(); i += 7) {
    auto r = t.insert(pts[i]);
    REQUIRE_FALSE(r.inserted);
    REQUIRE(r.vertex == ids[i]);
    REQUIRE(t.multiplicity(ids[i]) == 2);
  }
  const std::size_t dups = (pts.size() + 6) / 7;
  REQUIRE(t.number_of_vertices() == pts.size());
  REQUIRE((canonical_tets(t, pts) == before));
  REQUIRE(t.stats().duplicates == stats_before.duplicates + dups);
  REQUIRE(t.stats().insertions == stats_before.insertions + dups);
  auto r = t.insert(pts[0]);
  REQUIRE_FALSE(r.inserted);
  REQUIRE(t.multiplicity(ids[0]) == 3);
  REQUIRE(t.multiplicity(ids[1]) == 1);
  require_valid(t);

  SECTION("negative zero equals zero") {
    pdt::Triangulation u;
    auto a = u.insert({0, 0, 0});
    auto b = u.insert({-0.0, 0.0, -0.0});
    REQUIRE_FALSE(b.inserted);
    REQUIRE(b.vertex == a.vertex);
    REQUIRE(u.number_of_vertices() == 1);
  }
  SECTION("duplicates in lower dimensions") {
    pdt::Triangulation u;
    for (int k = 0; k < 3; ++k) {
      u.insert({0, 0, 0});
      u.insert({1, 1, 1});
      u.insert({2, 2, 2});
      u.insert({2, 0, 0});
    }
    REQUIRE(u.number_of_vertices() == 4);
    REQUIRE(u.dimension() == 2);
    for (auto v : u.vertices()) REQUIRE(u.multiplicity(v) == 3);
    require_valid(u);
  }
}

TEST_CASE("points on the convex hull", "[insert][degenerate]") {
  // Cube corners, then integer points on the faces, then inside.
  std::vector<Point3> pts;
  for (int x : {0, 4})
    for (int y : {0, 4})
      for (int z : {0, 4}) pts.push_back({double(x), double(y), double(z)});
  for (int i = 0; i <= 4; ++i)
    for (int j = 0; j <= 4; ++j)
      for (int f = 0; f < 2; ++f) {
        double c = f * 4.0;
        pts.push_back({c, double(i), double(j)});
        pts.push_back({double(i), c, double(j)});
        pts.push_back({double(i), double(j), c});
      }
  std::vector<Point3> shell = pts;
  check_orders(shell, 2, 31);  // duplicates among the face points
  pdt::Triangulation t;
  insert_all(t, shell);
  REQUIRE(t.number_of_vertices() == 5 * 5 * 5 - 3 * 3 * 3);
  std::vector<Point3> all = shell;
  for (const auto& p : random_points(60, 32, 0.5, 3.5)) {
    all.push_back(p);
    t.insert(p);
  }
  require_valid(t);
  require_same_as_cgal(t, all);
  // Points on a face after the interior exists.
  pdt::Triangulation u;
  std::vector<Point3> order = random_points(40, 33, 0.5, 3.5);
  for (int k = 0; k < 8; ++k) order.push_back(pts[k]);
  for (std::size_t k = 8; k < pts.size(); ++k) order.push_back(pts[k]);
  insert_all(u, order);
  require_valid(u);
  require_same_as_cgal(u, order);
}

TEST_CASE("real point sets equal CGAL", "[insert][real]") {
  struct Case {
    const char* file;
    std::size_t max_points;
    int shuffles;
  };
  const Case cases[] = {
      {"scans/cgal_b9.ply", 0, 1},
      {"degenerate/cgal_radar.xyz", 0, 1},
      {"degenerate/cgal_error_mesh-p_not_equal_0-min2.off", 0, 5},
      {"medical/cgal_femur.off", 0, 2},
      {"scans/stanford_bunny_bun000.ply", 20000, 1},
      {"scans/pdal_autzen_trim.xyz.gz", 20000, 1},
      // Heavily quantised, with exact duplicates; a stereo scan with few z values.
      {"scans/pcl_isprs_CSite4_orig-utm.ply", 20000, 0},
      {"scans/pcl_table_scene_mug_stereo_textured.xyz.gz", 20000, 0},
  };
  for (const Case& c : cases) {
    INFO("file " << c.file);
    std::vector<Point3> pts = read_or_empty(c.file, c.max_points);
    if (pts.empty()) continue;
    check_orders(pts, c.shuffles, 99);
  }
}

TEST_CASE("TetGen degenerate PLC node sets equal CGAL", "[insert][real][degenerate]") {
  const std::string dir = shared_data("degenerate/tetgen_testingdrafts");
  if (!std::filesystem::exists(dir)) {
    WARN("data directory absent, skipped: " << dir);
    return;
  }
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".smesh") files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  REQUIRE(!files.empty());
  for (const auto& f : files) {
    INFO("file " << f);
    std::vector<Point3> pts = pdt::read_points(f);
    REQUIRE(pts.size() >= 4);
    check_orders(pts, 5, 17);
  }
}

TEST_CASE("non-finite coordinates are rejected and change nothing", "[insert][error]") {
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                        -std::numeric_limits<double>::infinity()};
  auto check = [&](pdt::Triangulation& t, const std::vector<Point3>& pts) {
    const TetList before = canonical_tets(t, pts);
    const std::size_t nv = t.number_of_vertices(), nc = t.number_of_cells();
    const int dim = t.dimension();
    const auto vs = t.vertices();
    for (double b : bad)
      for (int coord = 0; coord < 3; ++coord) {
        Point3 p{0.25, 0.5, 0.75};
        (coord == 0 ? p.x : coord == 1 ? p.y : p.z) = b;
        INFO("coordinate " << coord << " = " << b);
        bool threw = false;
        try {
          t.insert(p);
        } catch (const pdt::Error& e) {
          threw = true;
          REQUIRE(e.code() == pdt::ErrorCode::non_finite_coordinate);
          REQUIRE(std::string(e.what()).size() > 0);
        }
        REQUIRE(threw);
        // With a hint too.
        REQUIRE_THROWS_AS(t.insert(p, pdt::Hint{vs.empty() ? pdt::no_vertex : vs[0], pdt::no_cell}), pdt::Error);
        REQUIRE(t.number_of_vertices() == nv);
        REQUIRE(t.number_of_cells() == nc);
        REQUIRE(t.dimension() == dim);
        REQUIRE((t.vertices() == vs));
      }
    // Several bad coordinates at once.
    REQUIRE_THROWS_AS(t.insert({bad[0], bad[1], bad[2]}), pdt::Error);
    REQUIRE((canonical_tets(t, pts) == before));
    REQUIRE(t.number_of_vertices() == nv);
    require_valid(t);
  };
  SECTION("empty") {
    pdt::Triangulation t;
    check(t, {});
    REQUIRE(t.dimension() == -1);
  }
  SECTION("dimension 2") {
    pdt::Triangulation t;
    std::vector<Point3> pts{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    insert_all(t, pts);
    check(t, pts);
  }
  SECTION("dimension 3") {
    pdt::Triangulation t;
    std::vector<Point3> pts = random_points(300, 41);
    insert_all(t, pts);
    check(t, pts);
    // Still usable afterwards.
    pts.push_back({0.25, 0.5, 0.75});
    REQUIRE(t.insert(pts.back()).inserted);
    require_same_as_cgal(t, pts);
  }
}

namespace {

pdt::LocateKind expected_kind(CDelaunay::Locate_type lt) {
  switch (lt) {
    case CDelaunay::CELL: return pdt::LocateKind::in_cell;
    case CDelaunay::FACET: return pdt::LocateKind::on_facet;
    case CDelaunay::EDGE: return pdt::LocateKind::on_edge;
    case CDelaunay::VERTEX: return pdt::LocateKind::on_vertex;
    case CDelaunay::OUTSIDE_CONVEX_HULL: return pdt::LocateKind::outside_hull;
    default: return pdt::LocateKind::none;
  }
}

// Checks that the cell t.locate returned for q is consistent with the kind.
void check_locate_cell(const pdt::Triangulation& t, const Point3& q, const pdt::LocateResult& r) {
  REQUIRE(r.cell != pdt::no_cell);
  REQUIRE(t.is_cell(r.cell));
  int inf = -1;
  for (int i = 0; i < 4; ++i)
    if (t.cell_vertex(r.cell, i) == pdt::infinite_vertex) inf = i;
  if (r.kind == pdt::LocateKind::outside_hull) {
    REQUIRE_FALSE(t.is_finite_cell(r.cell));
    REQUIRE(inf >= 0);
    // q strictly beyond the cell's finite facet.
    CPoint p[4];
    for (int i = 0; i < 4; ++i) p[i] = i == inf ? to_cgal(q) : to_cgal(t.point(t.cell_vertex(r.cell, i)));
    REQUIRE(CGAL::orientation(p[0], p[1], p[2], p[3]) == CGAL::POSITIVE);
    return;
  }
  REQUIRE(t.is_finite_cell(r.cell));
  REQUIRE(inf == -1);
  CPoint p[4];
  for (int i = 0; i < 4; ++i) p[i] = to_cgal(t.point(t.cell_vertex(r.cell, i)));
  int zeros = 0;
  for (int i = 0; i < 4; ++i) {
    CPoint s[4] = {p[0], p[1], p[2], p[3]};
    s[i] = to_cgal(q);
    auto o = CGAL::orientation(s[0], s[1], s[2], s[3]);
    REQUIRE(o != CGAL::NEGATIVE);  // q in the closed cell
    zeros += o == CGAL::ZERO;
  }
  const int want = r.kind == pdt::LocateKind::in_cell    ? 0
                   : r.kind == pdt::LocateKind::on_facet ? 1
                   : r.kind == pdt::LocateKind::on_edge  ? 2
                                                         : 3;
  REQUIRE(zeros == want);
  if (r.kind == pdt::LocateKind::on_vertex) {
    REQUIRE(t.is_vertex(r.vertex));
    REQUIRE(t.point(r.vertex) == q);
    bool in_cell = false;
    for (int i = 0; i < 4; ++i) in_cell |= t.cell_vertex(r.cell, i) == r.vertex;
    REQUIRE(in_cell);
  }
}

}  // namespace

TEST_CASE("locate reports the right kind and cell", "[insert][locate]") {
  SECTION("one tetrahedron, by hand") {
    pdt::Triangulation t;
    auto o = t.insert({0, 0, 0}).vertex;
    t.insert({4, 0, 0});
    t.insert({0, 4, 0});
    t.insert({0, 0, 4});
    struct Q {
      Point3 p;
      pdt::LocateKind k;
    };
    const Q qs[] = {
        {{1, 1, 1}, pdt::LocateKind::in_cell},       {{1, 1, 0}, pdt::LocateKind::on_facet},
        {{1, 1, 2}, pdt::LocateKind::on_facet},      {{2, 0, 0}, pdt::LocateKind::on_edge},
        {{0, 2, 2}, pdt::LocateKind::on_edge},       {{0, 0, 0}, pdt::LocateKind::on_vertex},
        {{5, 5, 5}, pdt::LocateKind::outside_hull},  {{-1, 1, 1}, pdt::LocateKind::outside_hull},
        {{8, 0, 0}, pdt::LocateKind::outside_hull},  {{2, 2, 1}, pdt::LocateKind::outside_hull},
    };
    for (const auto& q : qs) {
      INFO("query " << str(q.p));
      auto r = t.locate(q.p);
      REQUIRE(r.kind == q.k);
      check_locate_cell(t, q.p, r);
    }
    REQUIRE(t.locate({0, 0, 0}).vertex == o);
  }

  SECTION("lattice triangulation: cell centroids, facet and edge points, vertices") {
    std::vector<Point3> pts;
    std::mt19937_64 rng(51);
    for (int k = 0; k < 200; ++k) pts.push_back({double(rng() % 16), double(rng() % 16), double(rng() % 16)});
    pdt::Triangulation t;
    insert_all(t, pts);
    REQUIRE(t.dimension() == 3);
    auto cells = t.finite_cells();
    std::size_t checked = 0;
    for (std::size_t c = 0; c < cells.size(); c += 5) {
      Point3 v[4];
      for (int i = 0; i < 4; ++i) v[i] = t.point(cells[c][i]);
      // Exact dyadic combinations of integer points.
      Point3 in{(v[0].x + v[1].x + v[2].x + v[3].x) / 4, (v[0].y + v[1].y + v[2].y + v[3].y) / 4,
                (v[0].z + v[1].z + v[2].z + v[3].z) / 4};
      Point3 fa{(v[0].x + v[1].x + 2 * v[2].x) / 4, (v[0].y + v[1].y + 2 * v[2].y) / 4,
                (v[0].z + v[1].z + 2 * v[2].z) / 4};
      Point3 ed{(v[1].x + v[3].x) / 2, (v[1].y + v[3].y) / 2, (v[1].z + v[3].z) / 2};
      INFO("cell " << c);
      auto ri = t.locate(in);
      REQUIRE(ri.kind == pdt::LocateKind::in_cell);
      check_locate_cell(t, in, ri);
      auto rf = t.locate(fa);
      REQUIRE(rf.kind == pdt::LocateKind::on_facet);
      check_locate_cell(t, fa, rf);
      auto re = t.locate(ed);
      REQUIRE(re.kind == pdt::LocateKind::on_edge);
      check_locate_cell(t, ed, re);
      auto rv = t.locate(v[c % 4], pdt::Hint{cells[c][(c + 1) % 4], pdt::no_cell});
      REQUIRE(rv.kind == pdt::LocateKind::on_vertex);
      REQUIRE(rv.vertex == cells[c][c % 4]);
      check_locate_cell(t, v[c % 4], rv);
      ++checked;
    }
    REQUIRE(checked > 10);
  }

  SECTION("random queries agree with CGAL's locate") {
    std::vector<Point3> pts = random_points(2000, 61, 0.1, 0.9);
    pdt::Triangulation t;
    insert_all(t, pts);
    std::vector<std::pair<CPoint, std::uint32_t>> cp;
    for (std::uint32_t i = 0; i < pts.size(); ++i) cp.emplace_back(to_cgal(pts[i]), i);
    CDelaunay dt(cp.begin(), cp.end());
    std::mt19937_64 rng(62);
    std::vector<Point3> queries = random_points(2000, 63, -0.2, 1.2);
    for (int k = 0; k < 200; ++k) queries.push_back(pts[rng() % pts.size()]);
    // On the hull: a vertex of an infinite facet, and midpoints of hull edges.
    for (auto f = dt.finite_facets_begin(); f != dt.finite_facets_end(); ++f) {
      if (!dt.is_infinite(f->first) && !dt.is_infinite(f->first->neighbor(f->second))) continue;
      const auto& a = f->first->vertex((f->second + 1) % 4)->point();
      const auto& b = f->first->vertex((f->second + 2) % 4)->point();
      queries.push_back({(a.x() + b.x()) / 2, (a.y() + b.y()) / 2, (a.z() + b.z()) / 2});
    }
    std::size_t n = 0;
    for (std::size_t k = 0; k < queries.size(); ++k) {
      const Point3& q = queries[k];
      CDelaunay::Locate_type lt;
      int li, lj;
      dt.locate(to_cgal(q), lt, li, lj);
      auto r = t.locate(q);
      INFO("query " << str(q));
      REQUIRE(r.kind == expected_kind(lt));
      check_locate_cell(t, q, r);
      // With a hint (any vertex): same kind.
      auto rh = t.locate(q, pdt::Hint{t.vertices()[k % t.number_of_vertices()], pdt::no_cell});
      REQUIRE(rh.kind == r.kind);
      ++n;
    }
    REQUIRE(n > 2200);
  }
}

TEST_CASE("nearest_vertex equals brute force", "[insert][nearest]") {
  auto brute_check = [](const pdt::Triangulation& t, const Point3& q) {
    const auto vs = t.vertices();
    pdt::VertexId best = vs.at(0);
    for (auto v : vs)
      if (CGAL::compare_distance_to_point(to_cgal(q), to_cgal(t.point(v)), to_cgal(t.point(best))) == CGAL::SMALLER)
        best = v;
    pdt::VertexId got = t.nearest_vertex(q);
    INFO("query " << str(q) << " got " << got << " best " << best);
    REQUIRE(t.is_vertex(got));
    REQUIRE(CGAL::compare_distance_to_point(to_cgal(q), to_cgal(t.point(got)), to_cgal(t.point(best))) ==
            CGAL::EQUAL);
  };
  SECTION("uniform points, queries inside and outside the hull") {
    pdt::Triangulation t;
    insert_all(t, random_points(1500, 71));
    for (const auto& q : random_points(300, 72, -0.5, 1.5)) brute_check(t, q);
    for (const auto& v : t.vertices()) {
      if (v % 50) continue;
      REQUIRE(t.nearest_vertex(t.point(v)) == v);
    }
  }
  SECTION("lattice points, half-integer queries (ties)") {
    pdt::Triangulation t;
    std::vector<Point3> pts = lattice(5);
    shuffle(pts, 73);
    insert_all(t, pts);
    std::mt19937_64 rng(74);
    for (int k = 0; k < 200; ++k)
      brute_check(t, {double(rng() % 13) / 2 - 1, double(rng() % 13) / 2 - 1, double(rng() % 13) / 2 - 1});
  }
  SECTION("lower dimensions") {
    pdt::Triangulation t;
    t.insert({0, 0, 0});
    brute_check(t, {5, 5, 5});
    t.insert({1, 0, 0});
    brute_check(t, {0.75, 3, 0});
    brute_check(t, {0.25, 3, 0});
    t.insert({0, 1, 0});
    REQUIRE(t.dimension() == 2);
    for (const auto& q : random_points(30, 75, -1, 2)) brute_check(t, q);
  }
}

TEST_CASE("hints do not change the result", "[insert][hint]") {
  for (pdt::Distribution d : {pdt::Distribution::uniform, pdt::Distribution::grid, pdt::Distribution::sphere}) {
    INFO("distribution " << pdt::to_string(d));
    std::vector<Point3> pts = generated_points(d, 2000, 5);
    const CgalResult ref = cgal_reference(pts);
    pdt::Triangulation a, b, c;
    pdt::VertexId prev = pdt::no_vertex, first = pdt::no_vertex;
    std::mt19937_64 rng(6);
    for (std::size_t i = 0; i < pts.size(); ++i) {
      auto r = a.insert(pts[i], pdt::Hint{prev, pdt::no_cell});
      prev = r.vertex;
      // A far, arbitrary hint: the first vertex.
      auto rb = b.insert(pts[i], pdt::Hint{first, pdt::no_cell});
      if (first == pdt::no_vertex) first = rb.vertex;
      // A cell hint, when there are cells.
      pdt::CellId hc = pdt::no_cell;
      if (c.dimension() == 3) {
        for (pdt::CellId id = static_cast<pdt::CellId>(rng() % c.cell_id_bound()); id < c.cell_id_bound(); ++id)
          if (c.is_cell(id)) {
            hc = id;
            break;
          }
      }
      c.insert(pts[i], pdt::Hint{pdt::no_vertex, hc});
    }
    for (pdt::Triangulation* t : {&a, &b, &c}) {
      require_valid(*t);
      REQUIRE((canonical_tets(*t, pts) == ref.tets));
    }
  }
}

TEST_CASE("the jump grid follows where the vertices are", "[insert][locate]") {
  // A walk starts from the vertex of the point's grid slot, so its length
  // grows with the vertices between that vertex and the point. A uniform grid
  // over the bounding box gives points near a line, or on a surface, tens of
  // vertices per slot where they are (walks of 13 to 21 steps on the scans in
  // ../shared/data); the tree of grids keeps about two per slot.
  for (pdt::Distribution d : {pdt::Distribution::uniform, pdt::Distribution::line, pdt::Distribution::sphere}) {
    INFO("distribution " << pdt::to_string(d));
    const std::vector<Point3> pts = generated_points(d, 40000, 12);
    pdt::Triangulation t;
    for (const Point3& p : pts) t.insert(p);
    const auto& m = pdt::detail::impl_of(t);
    REQUIRE(m.grid.slot_count > 0);
    REQUIRE(m.grid.slot_count <= t.number_of_vertices());
    std::map<std::size_t, std::size_t> in_slot;
    for (pdt::VertexId v = 1; v < t.vertex_id_bound(); ++v)
      if (t.is_vertex(v)) ++in_slot[m.grid.slot_of(m.verts[v].p)];
    // The mean, over vertices, of the vertices in the same slot.
    double sharing = 0;
    for (const auto& [slot, count] : in_slot) sharing += static_cast<double>(count) * static_cast<double>(count);
    sharing /= static_cast<double>(t.number_of_vertices());
    const double steps = static_cast<double>(t.stats().walk_steps) / static_cast<double>(pts.size());
    INFO("vertices per slot, seen from a vertex: " << sharing << "; slots " << m.grid.slot_count
                                                   << "; walk steps per insertion " << steps);
    // A uniform grid: 3.5, 208 and 20 vertices per slot, walks of 6, 15 and
    // 127 steps. Points on a sphere make cells that span the ball, so their
    // walks stay long whatever the start.
    REQUIRE(sharing < 10);
    if (d != pdt::Distribution::sphere) REQUIRE(steps < 10);
  }
}

TEST_CASE("the engine's jump grid of equal slots is the same built in parallel or not", "[insert][locate]") {
  // The engine rebuilds it with the world stopped, on every thread of the
  // arena: each slot must name the largest id among the live vertices it
  // holds, as one thread filling them in id order leaves it.
  std::vector<Point3> pts = generated_points(pdt::Distribution::uniform, 60000, 21);
  pdt::Triangulation t;
  const std::vector<pdt::InsertResult> made = t.insert_batch(pts);
  for (std::size_t k = 0; k < made.size(); k += 3) t.remove(made[k].vertex);  // some ids free
  const auto& m = pdt::detail::impl_of(t);
  const auto serial = pdt::detail::JumpGrid::build_equal(m.verts, 20000, false);
  tbb::task_arena arena(4);
  const auto parallel = arena.execute([&] { return pdt::detail::JumpGrid::build_equal(m.verts, 20000, true); });
  REQUIRE(serial.slot_count == parallel.slot_count);
  REQUIRE(serial.slot_count <= 20000);
  REQUIRE(serial.slot_count >= 8000);  // k^3 with k = floor(cbrt(20000)) = 27
  CHECK(serial.built_for == t.number_of_vertices());
  CHECK(parallel.built_for == t.number_of_vertices());
  std::vector<pdt::VertexId> largest(serial.slot_count, pdt::no_vertex);
  std::vector<std::size_t> count(serial.slot_count, 0);
  for (pdt::VertexId v = 1; v < m.verts.size(); ++v)
    if (t.is_vertex(v)) {
      const std::size_t s = serial.slot_of(m.verts[v].p);
      pdt::VertexId& l = largest[s];
      if (l == pdt::no_vertex || l < v) l = v;
      ++count[s];
    }
  std::size_t differ = 0, filled = 0, crowded = 0;
  for (std::size_t s = 0; s < serial.slot_count; ++s) {
    differ += serial.get(s) != largest[s] || parallel.get(s) != largest[s];
    filled += largest[s] != pdt::no_vertex;
    if (count[s] > pdt::detail::JumpGrid::crowded_slot) crowded += count[s];
  }
  CHECK(differ == 0);
  CHECK(filled > serial.slot_count / 2);
  // The vertices in crowded slots, counted alike (none here: about 2 per slot).
  CHECK(serial.crowded == crowded);
  CHECK(parallel.crowded == crowded);
  CHECK(crowded < t.number_of_vertices() / 100);
}

TEST_CASE("the kernel's jump grid follows a region filled after its build", "[insert][locate]") {
  // 20k uniform points, then 20k in a cube of side 1e-4, one at a time (a
  // refiner refining one zone). The grid built for the first half holds the
  // cube in one slot until the vertex count doubles, and every walk crossed
  // the cube from the slot's last vertex (35 steps per insertion there; 12
  // now). Walks that stay long now rebuild the grid early (WalkWatch).
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts;
  for (int i = 0; i < 20000; ++i) pts.push_back({u(rng), u(rng), u(rng)});
  for (int i = 0; i < 20000; ++i) pts.push_back({0.4 + 1e-4 * u(rng), 0.5 + 1e-4 * u(rng), 0.6 + 1e-4 * u(rng)});
  pdt::Triangulation t;
  for (std::size_t i = 0; i < 20000; ++i) t.insert(pts[i]);
  const std::uint64_t steps_before = t.stats().walk_steps;
  for (std::size_t i = 20000; i < pts.size(); ++i) t.insert(pts[i]);
  const double steps = double(t.stats().walk_steps - steps_before) / 20000.0;
  INFO("walk steps per insertion in the cube " << steps);
  CHECK(steps < 15);
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("walks stay short after most vertices are removed, in the kernel and in an engine", "[insert][locate][remove]") {
  // A refiner's coarsening: 60k vertices removed down to 600, then 10k
  // inserted. A removed vertex's slot takes a link vertex, but slots that
  // had taken it from earlier removals kept naming it: most slots came to
  // name dead vertices and walks started far away (48 steps an insertion
  // instead of 6). The grid is rebuilt once a quarter of the vertices it was
  // built for remain (the kernel at its removals, an engine's workers as
  // they go), and an engine does not take over a grid built for far more.
  const std::vector<Point3> pts = generated_points(pdt::Distribution::uniform, 60000, 31);
  const std::vector<Point3> more = generated_points(pdt::Distribution::uniform, 10000, 32);
  std::vector<Point3> expected(pts.begin(), pts.begin() + 600);
  expected.insert(expected.end(), more.begin(), more.end());
  auto steps_per_insertion = [](const pdt::TriangulationStats& before, const pdt::TriangulationStats& after) {
    return static_cast<double>(after.walk_steps - before.walk_steps) /
           static_cast<double>(after.insertions - before.insertions);
  };
  SECTION("the kernel") {
    pdt::Triangulation t;
    std::vector<pdt::VertexId> ids;
    for (const Point3& p : pts) ids.push_back(t.insert(p).vertex);
    for (std::size_t i = ids.size(); i-- > 600;) t.remove(ids[i]);
    const pdt::TriangulationStats before = t.stats();
    for (const Point3& p : more) (void)t.insert(p);
    const double steps = steps_per_insertion(before, t.stats());
    INFO("walk steps per insertion after the removals " << steps);
    CHECK(steps < 12);
    require_valid(t);
    require_same_as_cgal(t, expected);
  }
  SECTION("an engine, on a grid the kernel built for all the points") {
    pdt::Triangulation t;
    const std::vector<pdt::InsertResult> in = t.insert_batch(pts);
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::EngineOptions opts;
      opts.workers = 2;
      {
        pdt::Engine e(t, pdt::Box{{0, 0, 0}, {1, 1, 1}}, opts);
        for (std::size_t i = 600; i < in.size(); ++i) e.remove(in[i].handle(), {});
        e.drain();
        // The workers rebuilt it as the vertices went (built for 60k before).
        INFO("grid built for " << pdt::detail::impl_of(t).grid.built_for);
        CHECK(pdt::detail::impl_of(t).grid.built_for < 15000);
      }
      const pdt::TriangulationStats before = t.stats();
      {
        pdt::Engine e(t, pdt::Box{{0, 0, 0}, {1, 1, 1}}, opts);
        for (const Point3& p : more) e.insert(p, {});
        e.drain();
      }
      const double steps = steps_per_insertion(before, t.stats());
      INFO("walk steps per insertion after the removals " << steps);
      CHECK(steps < 12);
    });
    require_valid(t);
    require_same_as_cgal(t, expected);
  }
}

TEST_CASE("an engine's jump grid follows a cluster far smaller than the box", "[insert][locate]") {
  // Half the points uniform in the unit cube, half in a cube of side 1e-4:
  // equal slots would hold the cluster in one slot, and a walk from there
  // would cross the cluster (tens of steps). build_equal counts the vertices
  // in crowded slots; the engine's rebuild then keeps the equal slots and cuts
  // the crowded ones again (build_split), in at most twice the slots asked for.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts;
  for (int i = 0; i < 40000; ++i)
    pts.push_back(i % 2 ? Point3{u(rng), u(rng), u(rng)} : Point3{0.3 + 1e-4 * u(rng), 0.6 + 1e-4 * u(rng), 0.2 + 1e-4 * u(rng)});
  pdt::Triangulation t;
  (void)t.insert_batch(pts);
  auto& m = pdt::detail::impl_of(t);
  const auto equal = pdt::detail::JumpGrid::build_equal(m.verts, 20000, false);
  CHECK(equal.crowded >= 20000);  // the cluster's vertices at least
  CHECK(5 * equal.crowded > 2 * equal.built_for);  // over 40%: grid_rebuild's rule
  m.grid_growth = pdt::Triangulation::Impl::GridGrowth::engine;
  m.grid_rebuild(20000, false, 1u << 23);
  const pdt::detail::JumpGrid& g = m.grid;
  REQUIRE(g.node_count > 1);  // cut, not equal slots alone
  REQUIRE(g.slot_count <= 40000);  // twice the slots asked for
  // Seen from a vertex, the mean number of vertices sharing its slot, in the
  // cluster and out of it: about what equal slots give uniform points.
  std::vector<std::size_t> count(g.slot_count, 0);
  for (pdt::VertexId v = 1; v < m.verts.size(); ++v)
    if (t.is_vertex(v)) ++count[g.slot_of(m.verts[v].p)];
  double in_cluster = 0, outside = 0;
  std::size_t n_in = 0, n_out = 0;
  for (pdt::VertexId v = 1; v < m.verts.size(); ++v) {
    if (!t.is_vertex(v)) continue;
    const Point3 p{m.verts[v].p.x(), m.verts[v].p.y(), m.verts[v].p.z()};
    const bool in = p.x >= 0.3 && p.x <= 0.3 + 1e-4 && p.y >= 0.6 && p.y <= 0.6 + 1e-4;
    (in ? in_cluster : outside) += static_cast<double>(count[g.slot_of(m.verts[v].p)]);
    ++(in ? n_in : n_out);
  }
  INFO("sharing in the cluster " << in_cluster / n_in << ", outside " << outside / n_out << ", slots " << g.slot_count);
  CHECK(in_cluster / static_cast<double>(n_in) < 10);
  CHECK(outside / static_cast<double>(n_out) < 10);
  // The same grid built on one thread or on four.
  const auto serial = pdt::detail::JumpGrid::build_split(m.verts, 20000, 40000, false);
  tbb::task_arena arena(4);
  const auto parallel =
      arena.execute([&] { return pdt::detail::JumpGrid::build_split(m.verts, 20000, 40000, true); });
  REQUIRE(serial.check());
  REQUIRE(serial.node_count == parallel.node_count);
  REQUIRE(serial.slot_count == parallel.slot_count);
  REQUIRE(serial.slot_count <= 40000);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < serial.node_count; ++i)
    differ += serial.nodes[i].first != parallel.nodes[i].first || serial.nodes[i].k_leaf != parallel.nodes[i].k_leaf;
  for (std::size_t s = 0; s < serial.slot_count; ++s) differ += serial.get(s) != parallel.get(s);
  CHECK(differ == 0);
  // check() sees a broken encoding: a leaf's slots pointing past the end,
  // or two leaves covering one slot.
  {
    const pdt::detail::JumpGrid& broken = serial;  // its nodes are not const: the array is the grid's
    std::size_t leaf = 0;
    while (leaf < broken.node_count && !broken.nodes[leaf].leaf()) ++leaf;
    REQUIRE(leaf < broken.node_count);
    const std::uint32_t first = broken.nodes[leaf].first;
    broken.nodes[leaf].first = static_cast<std::uint32_t>(broken.slot_count);
    CHECK_FALSE(broken.check());
    std::size_t other = leaf + 1;
    while (other < broken.node_count && !broken.nodes[other].leaf()) ++other;
    REQUIRE(other < broken.node_count);
    broken.nodes[leaf].first = broken.nodes[other].first;
    CHECK_FALSE(broken.check());
    broken.nodes[leaf].first = first;
    CHECK(broken.check());
  }
  m.grid_growth = pdt::Triangulation::Impl::GridGrowth::kernel;
  require_valid(t);
}

TEST_CASE("a large insert_batch regrows the jump grid without noting each vertex, a small one notes them", "[insert][locate]") {
  // During a batch at least as large as the mesh, walks start at the last
  // vertex: its vertices are not noted in the grid one by one, but the grid
  // is still rebuilt from every vertex as the count doubles, so single
  // insertions after it walk as far as ever.
  const std::vector<Point3> pts = generated_points(pdt::Distribution::uniform, 30000, 13);
  pdt::Triangulation t;
  (void)t.insert_batch(std::span(pts).first(1000));
  const auto& m = pdt::detail::impl_of(t);
  const std::size_t before = m.grid.built_for;
  const std::vector<pdt::InsertResult> large = t.insert_batch(std::span(pts).subspan(1000, 20000));  // 20x the mesh
  REQUIRE(m.grid.built_for > before);
  REQUIRE(2 * m.grid.built_for + 64 > 21000);  // rebuilt at the last doubling
  REQUIRE(m.grid.slot_count > 0);
  for (std::size_t s = 0; s < m.grid.slot_count; ++s) {
    const pdt::VertexId v = m.grid.get(s);
    if (v != pdt::no_vertex) REQUIRE(t.is_vertex(v));
  }
  // The batch's last vertex, inserted after that rebuild, is not in it (noted,
  // it would be: no later vertex could take its slot).
  const pdt::VertexId last = large.back().vertex;
  REQUIRE(m.grid.built_for < 21000);
  REQUIRE(m.grid.get(m.grid.slot_of(m.verts[last].p)) != last);
  // A small batch (100 points into 21,000) notes its vertices.
  const std::vector<pdt::InsertResult> small = t.insert_batch(std::span(pts).subspan(21000, 100));
  std::size_t noted = 0;
  for (const pdt::InsertResult& r : small) noted += m.grid.get(m.grid.slot_of(m.verts[r.vertex].p)) == r.vertex;
  REQUIRE(noted > 90);  // all but those whose slot a later one of the 100 took
  // Single insertions after it walk a few steps, as after insertions one by one.
  const std::size_t steps_before = t.stats().walk_steps;
  for (std::size_t i = 21100; i < pts.size(); ++i) t.insert(pts[i]);
  const double steps = static_cast<double>(t.stats().walk_steps - steps_before) / static_cast<double>(pts.size() - 21100);
  INFO("walk steps per single insertion " << steps);
  REQUIRE(steps < 10);
  require_valid(t);
  REQUIRE((canonical_tets(t, pts) == cgal_reference(pts).tets));
  // The grid rebuilt during a batch follows the vertices, as any the kernel
  // builds: points near a line get a tree of nodes, not one level of equal
  // slots (the engine's kind).
  const std::vector<Point3> line = generated_points(pdt::Distribution::line, 20000, 14);
  pdt::Triangulation l;
  (void)l.insert_batch(line);
  REQUIRE(pdt::detail::impl_of(l).grid.node_count > 1);
}

TEST_CASE("walks stay short for boxes of any size, subnormal ones included", "[insert][locate][extreme]") {
  // A box whose extent is subnormal could not be scaled (res / extent
  // overflowed): every vertex fell in one slot, and 80,000 points walked 97
  // steps each. Integer lattice points times 2^-1074, 2^-1000, 1, 2^1000.
  for (double scale : {0x1p-1074, 0x1p-1000, 1.0, 0x1p1000}) {
    INFO("scale " << scale);
    std::mt19937_64 rng(5);
    std::uniform_int_distribution<int> coord(0, 1 << 20);
    std::vector<Point3> pts;
    for (int i = 0; i < 20000; ++i) pts.push_back({coord(rng) * scale, coord(rng) * scale, coord(rng) * scale});
    pdt::Triangulation t;
    for (const Point3& p : pts) t.insert(p);
    const double steps = static_cast<double>(t.stats().walk_steps) / static_cast<double>(pts.size());
    INFO("walk steps per insertion " << steps);
    CHECK(steps < 10);
    if (scale == 0x1p-1074) REQUIRE(canonical_tets(t, pts) == cgal_tets(pts));
  }
}

TEST_CASE("stale and out-of-range hints are harmless", "[insert][hint]") {
  // A hint is only advice: a refiner may hand over a vertex that has since
  // disappeared. The result must not depend on it.
  std::vector<Point3> pts = random_points(1500, 201);
  pdt::Triangulation t;
  std::vector<pdt::VertexId> ids = insert_all(t, pts);
  std::vector<Point3> all(pts.begin() + 100, pts.end());
  for (int k = 0; k < 100; ++k) t.remove(ids[k]);
  const std::vector<Point3> extra = random_points(400, 202, -0.2, 1.2);
  for (std::size_t k = 0; k < extra.size(); ++k) {
    pdt::Hint h;
    switch (k % 4) {
      case 0: h = {ids[k % 100], pdt::no_cell}; break;                       // removed vertex
      case 1: h = {t.vertex_id_bound() + 7, pdt::no_cell}; break;           // never issued
      case 2: h = {pdt::infinite_vertex, t.cell_id_bound() + 3}; break;     // infinite vertex, bad cell
      default: h = {pdt::no_vertex, static_cast<pdt::CellId>(k)}; break;    // any cell id, maybe free
    }
    t.insert(extra[k], h);
    all.push_back(extra[k]);
    const auto r = t.locate(extra[k], h);
    REQUIRE(r.kind == pdt::LocateKind::on_vertex);
  }
  require_valid(t);
  require_same_as_cgal(t, all);
}

TEST_CASE("the raw accessors refuse ids and slots out of range, naming the rule", "[insert][error]") {
  // A client iterating ids must get an error for a slip, never a read past
  // the records (found by an outside client: cell_vertex(0, 7) returned the
  // word after the cell's four).
  std::vector<Point3> pts = random_points(300, 211);
  pdt::Triangulation t;
  std::vector<pdt::VertexId> ids = insert_all(t, pts);
  t.remove(ids[0]);
  const pdt::CellId bound = t.cell_id_bound();
  pdt::CellId live = 0;
  while (!t.is_finite_cell(live)) ++live;
  auto code_of = [](auto&& call) {
    try {
      call();
    } catch (const pdt::Error& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find("Triangulation::") != std::string::npos);
      return static_cast<int>(e.code());
    }
    return -1;
  };
  const int invalid = static_cast<int>(pdt::ErrorCode::invalid_argument);
  const int unknown = static_cast<int>(pdt::ErrorCode::unknown_vertex);
  CHECK(code_of([&] { (void)t.cell_vertex(live, 4); }) == invalid);
  CHECK(code_of([&] { (void)t.cell_vertex(live, -1); }) == invalid);
  CHECK(code_of([&] { (void)t.cell_neighbor(live, 7); }) == invalid);
  CHECK(code_of([&] { (void)t.cell_vertex(bound, 0); }) == invalid);
  CHECK(code_of([&] { (void)t.cell_neighbor(pdt::no_cell, 0); }) == invalid);
  CHECK(code_of([&] { (void)t.cell_handle(bound + 5); }) == invalid);
  CHECK(code_of([&] { (void)t.point(ids[0]); }) == unknown);  // removed
  CHECK(code_of([&] { (void)t.point(pdt::infinite_vertex); }) == unknown);
  CHECK(code_of([&] { (void)t.point(t.vertex_id_bound() + 9); }) == unknown);
  CHECK(t.vertex_handle(ids[0]).incarnation == 0);
  // In range, they answer as before.
  for (int i = 0; i < 4; ++i) {
    const pdt::VertexId w = t.cell_vertex(live, i);
    REQUIRE(t.is_vertex(w));
    const Point3 p = t.point(w);
    CHECK(t.locate(p).kind == pdt::LocateKind::on_vertex);
    const pdt::CellId n = t.cell_neighbor(live, i);
    CHECK(t.is_cell(n));
  }
  CHECK(t.cell(t.cell_handle(live)).has_value());
  require_valid(t);
}

TEST_CASE("a vertex handle reads as dead in any other triangulation, a moved-over one included", "[insert][error]") {
  // Found by an outside client: after `t = Triangulation()` and the same
  // points again, the old handles read live (incarnations were counted per
  // triangulation, from 1), so remove(h) would have taken a vertex h never
  // named.
  const std::vector<Point3> pts = random_points(200, 212);
  pdt::Triangulation t;
  std::vector<pdt::VertexHandle> old;
  for (const Point3& p : pts) old.push_back(t.insert(p).handle());
  pdt::Triangulation other;
  for (const Point3& p : pts) other.insert(p);
  t = pdt::Triangulation();
  for (const Point3& p : pts) t.insert(p);
  for (const pdt::Triangulation* u : {&t, &other}) {
    for (const pdt::VertexHandle& h : old) {
      REQUIRE(u->is_vertex(h.id));  // the same ids are live again
      CHECK_FALSE(u->is_vertex(h));
    }
  }
  for (std::size_t k = 0; k < 10; ++k) {
    try {
      t.remove(old[k]);
      FAIL("a handle of another triangulation was accepted");
    } catch (const pdt::Error& e) {
      CHECK(e.code() == pdt::ErrorCode::unknown_vertex);
      // Named as a stale incarnation, not as a vertex never inserted: its id is live.
      INFO(e.what());
      CHECK(std::string(e.what()).find("the incarnation of it this removal names was already removed") !=
            std::string::npos);
    }
  }
  CHECK(t.number_of_vertices() == pts.size());
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("extreme but finite coordinates equal CGAL", "[insert][extreme]") {
  // Coordinates are used exactly, whatever their magnitude: predicates are
  // exact; nothing else (point location, grids) may overflow or underflow.
  auto scaled = [](std::size_t n, std::uint64_t seed, double scale, double offset) {
    std::vector<Point3> pts = random_points(n, seed, -1, 1);
    for (auto& p : pts) p = {offset + p.x * scale, offset + p.y * scale, offset + p.z * scale};
    return pts;
  };
  auto check = [](const std::vector<Point3>& pts) {
    pdt::Triangulation t;
    insert_all(t, pts);
    require_valid(t);
    require_same_as_cgal(t, pts);
  };
  SECTION("magnitude 1e300") { check(scaled(500, 211, 1e300, 0)); }
  SECTION("magnitude 1e-300") { check(scaled(500, 212, 1e-300, 0)); }
  SECTION("large offset, small extent") { check(scaled(500, 213, 1e-3, 1e9)); }
  SECTION("mixed magnitudes") {
    std::vector<Point3> pts = random_points(300, 214);
    pts.push_back({1e300, 0, 0});
    pts.push_back({0, -1e300, 1e-300});
    pts.push_back({-1e300, 1e300, 1e300});
    pts.push_back({1e-300, 1e-300, -1e-300});
    check(pts);
  }
  SECTION("subnormal coordinates: 4 points") {
    const double d = 1e-310;
    check({{0, 0, 0}, {d, 0, 0}, {0, d, 0}, {0, 0, d}});
  }
  SECTION("subnormal coordinates: many points") { check(scaled(300, 215, 1e-310, 0)); }
  SECTION("the largest doubles: 4 points") {
    const double m = std::numeric_limits<double>::max();
    check({{-m, -m, -m}, {m, -m, -m}, {-m, m, -m}, {-m, -m, m}});
  }
  SECTION("the largest doubles: cube corners and inside") {
    const double m = std::numeric_limits<double>::max();
    std::vector<Point3> pts;
    for (int x : {-1, 1})
      for (int y : {-1, 1})
        for (int z : {-1, 1}) pts.push_back({x * m, y * m, z * m});
    for (const auto& p : scaled(200, 216, m, 0)) pts.push_back(p);
    check(pts);
  }
}

TEST_CASE("cocircular coplanar start, then apexes", "[insert][degenerate]") {
  // Integer points on the circle x^2 + y^2 = 1105 (= 5*13*17: 32 of them):
  // the 2D triangulation is decided by the perturbation alone.
  std::vector<Point3> circle;
  for (int x = -34; x <= 34; ++x)
    for (int y = -34; y <= 34; ++y)
      if (x * x + y * y == 1105) circle.push_back({double(x), double(y), 0});
  REQUIRE(circle.size() == 32);
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    INFO("seed " << seed);
    std::vector<Point3> pts = circle;
    shuffle(pts, seed);
    pdt::Triangulation t;
    insert_all(t, pts);
    REQUIRE(t.dimension() == 2);
    require_valid(t);
    // An apex on the axis: cospherical with the whole circle.
    pts.push_back({0, 0, 7});
    t.insert(pts.back());
    REQUIRE(t.dimension() == 3);
    // Any triangulation of 32 points in convex position has 30 triangles.
    REQUIRE(t.number_of_finite_cells() == 30);
    require_valid(t);
    require_same_as_cgal(t, pts);
    pts.push_back({0, 0, -7});  // the mirror apex: all 34 points cospherical
    t.insert(pts.back());
    require_valid(t);
    require_same_as_cgal(t, pts);
    pts.push_back({0, 0, 0});  // the centre, on the plane
    t.insert(pts.back());
    require_valid(t);
    require_same_as_cgal(t, pts);
  }
}

TEST_CASE("coplanar start: apex positions", "[insert][degenerate]") {
  // The 3D triangulation is built from a 2D one when the first point leaves
  // the plane: every tetrahedron then has that apex, one per 2D triangle.
  std::vector<Point3> grid;
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 6; ++y) grid.push_back({double(x), double(y), 0});
  const std::size_t triangles = 2 * 8 * 6 - (2 * 8 + 2 * 6 - 4) - 2;  // 2n - h - 2
  const Point3 apexes[] = {{3, 2, 1},   {3.5, 2.5, -1}, {0, 0, 1},  {7, 5, -2}, {20, 20, 1},
                           {-5, 2, 0.5}, {3, -10, 3},   {7, 0, 1e-9}, {3.5, 2.5, 1e6}};
  for (const Point3& a : apexes) {
    for (std::uint64_t seed : {1, 2}) {
      INFO("apex " << str(a) << ", seed " << seed);
      std::vector<Point3> pts = grid;
      shuffle(pts, seed);
      pdt::Triangulation t;
      insert_all(t, pts);
      REQUIRE(t.dimension() == 2);
      pts.push_back(a);
      t.insert(a);
      REQUIRE(t.dimension() == 3);
      REQUIRE(t.number_of_finite_cells() == triangles);
      require_valid(t);
      require_same_as_cgal(t, pts);
      // A second apex on the other side, then more grid-like points.
      pts.push_back({a.x, a.y + 0.5, -a.z});
      t.insert(pts.back());
      for (int k = 0; k < 10; ++k) {
        pts.push_back({double(k % 8), double(k % 6), double(k % 3) - 1});
        t.insert(pts.back());
      }
      require_valid(t);
      require_same_as_cgal(t, pts);
    }
  }
  SECTION("a tilted plane with exact integer points") {
    // x + y + z = 6 with integer coordinates.
    std::vector<Point3> pts;
    for (int x = -4; x <= 6; ++x)
      for (int y = -4; y <= 6; ++y) pts.push_back({double(x), double(y), double(6 - x - y)});
    shuffle(pts, 3);
    pdt::Triangulation t;
    insert_all(t, pts);
    REQUIRE(t.dimension() == 2);
    pts.push_back({0, 0, 0});
    t.insert(pts.back());
    REQUIRE(t.dimension() == 3);
    require_valid(t);
    require_same_as_cgal(t, pts);
  }
}

TEST_CASE("insert_batch equals CGAL and reports each point's vertex in the batch's order", "[insert]") {
  std::vector<std::vector<Point3>> sets = {generated_points(pdt::Distribution::uniform, 5000, 11),
                                           generated_points(pdt::Distribution::line, 3000, 12), lattice(7),
                                           cospherical(325),
                                           // insert_batch gathers 1024 points at a time: whole chunks only
                                           generated_points(pdt::Distribution::uniform, 2048, 16)};
  // Duplicates inside one batch: the second copy raises the multiplicity.
  std::vector<Point3> dups = generated_points(pdt::Distribution::normal, 1000, 13);
  dups.insert(dups.end(), dups.begin(), dups.begin() + 300);
  sets.push_back(dups);
  for (const auto& pts : sets) {
    INFO(pts.size() << " points");
    pdt::Triangulation t;
    const std::vector<pdt::InsertResult> res = t.insert_batch(pts);
    REQUIRE(res.size() == pts.size());
    std::size_t fresh = 0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      REQUIRE(t.is_vertex(res[i].vertex));
      REQUIRE(t.point(res[i].vertex) == pts[i]);
      fresh += res[i].inserted;
    }
    REQUIRE(fresh == t.number_of_vertices());
    require_valid(t);
    require_same_as_cgal(t, pts);
    // A second batch on a non-empty triangulation, then removal of the first.
    std::vector<Point3> more = generated_points(pdt::Distribution::uniform, 500, pts.size());
    t.insert_batch(more);
    for (std::size_t i = 0; i < pts.size(); ++i) t.remove(res[i].vertex);
    require_valid(t);
    require_same_as_cgal(t, more);
  }
}

TEST_CASE("insert_batch with a NaN anywhere inserts nothing", "[insert][error]") {
  pdt::Triangulation t;
  const std::vector<Point3> base = generated_points(pdt::Distribution::uniform, 200, 14);
  t.insert_batch(base);
  const TetList before = canonical_tets(t, base);
  std::vector<Point3> bad = generated_points(pdt::Distribution::uniform, 100, 15);
  bad[57].y = std::numeric_limits<double>::quiet_NaN();
  try {
    t.insert_batch(bad);
    FAIL("no error");
  } catch (const pdt::Error& e) {
    REQUIRE(e.code() == pdt::ErrorCode::non_finite_coordinate);
  }
  REQUIRE(t.number_of_vertices() == base.size());
  REQUIRE(canonical_tets(t, base) == before);
  REQUIRE(t.insert_batch({}).empty());
}

TEST_CASE("a change hook that throws: the operation is done and the counts stay true in every dimension",
          "[insert][remove][hook]") {
  // changes.hpp: the sequential triangulation lets the hook's exception out
  // of insert/remove, the operation being done. Through dimensions 0..3 and
  // back, with duplicates.
  pdt::Triangulation t;
  int thrown = 0;
  t.set_change_hook([](const pdt::Changes&) { throw std::runtime_error("hook"); });
  const std::vector<Point3> pts{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}, {1, 1, 1}, {1, 0, 0}};
  auto check = [&](std::size_t expected) {
    std::string why;
    REQUIRE(t.validate(&why));
    REQUIRE(t.number_of_vertices() == expected);
    REQUIRE(t.vertices().size() == expected);
  };
  std::size_t distinct = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const bool fresh = i + 1 < pts.size();  // the last one is a duplicate (no report, nothing thrown)
    try {
      t.insert(pts[i]);
    } catch (const std::runtime_error&) {
      ++thrown;
    }
    distinct += fresh;
    check(distinct);
  }
  REQUIRE(t.dimension() == 3);
  REQUIRE(thrown == 7);
  while (t.number_of_vertices() > 0) {
    const pdt::VertexId v = t.vertices().front();
    const std::uint32_t mult = t.multiplicity(v);
    try {
      t.remove(v);
    } catch (const std::runtime_error&) {
      ++thrown;
    }
    check(mult > 1 ? distinct : --distinct);
  }
  REQUIRE(t.dimension() == -1);
}

TEST_CASE("a sequential change hook's queries see the change complete, counts included, in every dimension",
          "[insert][remove][hook]") {
  // The hook runs inside the operation but after the change is made: every
  // const query, validate() included, agrees with what it reports.
  pdt::Triangulation t;
  std::size_t reports = 0;
  std::vector<std::string> wrong;
  t.set_change_hook([&](const pdt::Changes& c) {
    ++reports;
    std::string why;
    if (!t.validate(&why)) wrong.push_back("validate: " + why);
    if (t.number_of_vertices() != t.vertices().size()) wrong.push_back("vertex count");
    if (t.number_of_finite_cells() != t.finite_cells().size()) wrong.push_back("finite cell count");
    for (const pdt::CellView& v : c.created)
      if (!t.cell(v.handle)) wrong.push_back("a created cell reads dead");
    if (c.kind == pdt::OpKind::insert && !t.is_vertex(c.vertex)) wrong.push_back("the inserted vertex is not live");
    if (c.kind == pdt::OpKind::remove && t.is_vertex(c.vertex)) wrong.push_back("the removed vertex is live");
  });
  // Through dimensions 0..3 one point at a time, a batch, then back to empty.
  const std::vector<Point3> first{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}};
  for (const Point3& p : first) (void)t.insert(p);
  (void)t.insert_batch(random_points(200, 61));
  while (t.number_of_vertices() > 0) (void)t.remove(t.vertices().back());
  CHECK(reports > 400);
  INFO((wrong.empty() ? std::string() : wrong.front()));
  CHECK(wrong.empty());
}

TEST_CASE("a change hook may not change its own triangulation: refused, naming the rule", "[insert][remove][hook]") {
  // The hook reports a change still being made: inserting, removing,
  // clearing, replacing the hook (the running std::function) or moving the
  // triangulation from it would pull the ground from under that call.
  pdt::Triangulation t;
  for (const Point3& p : random_points(50, 3)) t.insert(p);
  std::vector<std::string> refusals;
  const pdt::VertexId some = t.vertices().front();
  t.set_change_hook([&](const pdt::Changes&) {
    auto refused = [&](auto&& call) {
      try {
        call();
        refusals.push_back("accepted");
      } catch (const pdt::Error& e) {
        refusals.push_back(e.code() == pdt::ErrorCode::invalid_argument ? e.what() : "wrong code");
      }
    };
    refused([&] { t.insert({0.5, 0.5, 0.5}); });
    refused([&] { t.remove(some); });
    refused([&] { t.clear(); });
    refused([&] { t.set_change_hook({}); });
    refused([&] { pdt::Triangulation moved(std::move(t)); });
    refused([&] {
      pdt::Triangulation other;
      t = std::move(other);
    });
    refused([&] { pdt::Engine e(t, {{-1, -1, -1}, {2, 2, 2}}, pdt::EngineOptions{}); });
  });
  t.insert({0.25, 0.75, 0.5});
  REQUIRE(refusals.size() == 7);
  for (const std::string& why : refusals) {
    INFO(why);
    CHECK(why.find("the triangulation's own change hook") != std::string::npos);
  }
  // Nothing changed but the insertion that ran the hook; the hook is kept.
  std::string why;
  REQUIRE(t.validate(&why));
  REQUIRE(t.number_of_vertices() == 51);
  REQUIRE(t.is_vertex(some));
  t.set_change_hook({});  // outside the hook: fine
  t.insert({0.75, 0.25, 0.5});
  REQUIRE(refusals.size() == 7);
}
