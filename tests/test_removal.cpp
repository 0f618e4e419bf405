// SPDX-License-Identifier: MIT
// Removal: after any interleaving of insertions and removals pdt equals CGAL's
// Delaunay triangulation of the surviving points; removal undoes insertion
// exactly; dimensions drop and come back; bad ids are rejected without change.
#include <algorithm>
#include <array>
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
#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"
#include "triangulation_impl.hpp"  // a test pushes cell incarnations to their last value

using namespace pdt_test;
using pdt::Point3;

namespace {

// A triangulation with its own bookkeeping of the live insertions, so the
// expected surviving point set is known independently of pdt.
struct Tracked {
  pdt::Triangulation t;
  struct Live {
    Point3 p;
    pdt::VertexId v;
  };
  std::vector<Live> live;  // one entry per insertion not yet undone
  std::unordered_map<Point3, int, PointHash> count;
  std::vector<std::string> log;  // the operations, for reproducing a failure
  bool keep_log = false;

  pdt::VertexId insert(const Point3& p) {
    auto r = t.insert(p);
    int& c = count[p];
    REQUIRE(r.inserted == (c == 0));
    REQUIRE(t.is_vertex(r.vertex));
    REQUIRE(t.point(r.vertex) == p);
    ++c;
    REQUIRE(t.multiplicity(r.vertex) == static_cast<std::uint32_t>(c));
    live.push_back({p, r.vertex});
    if (keep_log) log.push_back("insert " + str(p) + " -> " + std::to_string(r.vertex));
    return r.vertex;
  }
  // Undoes live insertion k. keep_order: the others keep their order
  // (else the last one takes slot k).
  void remove_at(std::size_t k, bool keep_order = false) {
    Live l = live[k];
    if (keep_order) {
      live.erase(live.begin() + static_cast<std::ptrdiff_t>(k));
    } else {
      live[k] = live.back();
      live.pop_back();
    }
    if (keep_log) log.push_back("remove " + std::to_string(l.v) + " " + str(l.p));
    int& c = count[l.p];
    REQUIRE(c > 0);
    const std::size_t nv = t.number_of_vertices();
    auto r = t.remove(l.v);
    --c;
    if (c == 0) {
      REQUIRE(r == pdt::RemoveResult::removed);
      REQUIRE_FALSE(t.is_vertex(l.v));
      REQUIRE(t.multiplicity(l.v) == 0);
      REQUIRE(t.number_of_vertices() == nv - 1);
      count.erase(l.p);
    } else {
      REQUIRE(r == pdt::RemoveResult::multiplicity_lowered);
      REQUIRE(t.is_vertex(l.v));
      REQUIRE(t.multiplicity(l.v) == static_cast<std::uint32_t>(c));
      REQUIRE(t.number_of_vertices() == nv);
    }
  }
  std::vector<Point3> expected() const {
    std::vector<Point3> pts;
    for (const auto& l : live) pts.push_back(l.p);
    return pts;
  }
  void check() {
    std::string ops;
    if (keep_log)
      for (const auto& s : log) ops += s + "\n";
    INFO("operations:\n" << ops);
    REQUIRE(t.number_of_vertices() == count.size());
    require_same_as_cgal(t, expected());
  }
};

// Inserts pts in a random interleaving with removals of random live
// insertions (probability p_remove per step) and occasional re-insertions of
// live points (duplicates). Calls `after_op` after every operation.
template <class F>
void interleave(Tracked& tr, const std::vector<Point3>& pts, double p_remove, std::uint64_t seed, F after_op) {
  std::mt19937_64 rng(seed);
  std::size_t next = 0;
  while (next < pts.size()) {
    double u = uniform(rng, 0, 1);
    if (!tr.live.empty() && u < p_remove) {
      tr.remove_at(rng() % tr.live.size());
    } else if (!tr.live.empty() && u < p_remove + 0.03) {
      tr.insert(tr.live[rng() % tr.live.size()].p);
    } else {
      tr.insert(pts[next++]);
    }
    after_op();
  }
}

// Hull vertices: the finite vertices of infinite cells.
std::vector<pdt::VertexId> hull_vertices(const pdt::Triangulation& t) {
  std::set<pdt::VertexId> s;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
    if (!t.is_cell(c) || t.is_finite_cell(c)) continue;
    for (int i = 0; i < 4; ++i)
      if (t.cell_vertex(c, i) != pdt::infinite_vertex) s.insert(t.cell_vertex(c, i));
  }
  return {s.begin(), s.end()};
}

struct Snapshot {
  TetList tets;
  std::vector<pdt::VertexId> vertices;
  std::size_t cells;
  int dim;
};
Snapshot snapshot(const pdt::Triangulation& t, const PointIndex& index) {
  return {canonical_tets(t, index), t.vertices(), t.number_of_cells(), t.dimension()};
}
void require_unchanged(const pdt::Triangulation& t, const PointIndex& index, const Snapshot& s) {
  REQUIRE(t.dimension() == s.dim);
  REQUIRE((t.vertices() == s.vertices));
  REQUIRE(t.number_of_cells() == s.cells);
  REQUIRE((canonical_tets(t, index) == s.tets));
}

const pdt::Distribution interleave_dists[] = {pdt::Distribution::uniform, pdt::Distribution::normal,
                                              pdt::Distribution::grid, pdt::Distribution::sphere,
                                              pdt::Distribution::line};

}  // namespace

TEST_CASE("random interleavings of insertions and removals equal CGAL", "[remove]") {
  for (pdt::Distribution d : interleave_dists) {
    for (std::uint64_t seed = 1; seed <= 2; ++seed) {
      INFO("distribution " << pdt::to_string(d) << ", seed " << seed);
      std::vector<Point3> pts = generated_points(d, 2500, seed);
      Tracked tr;
      std::size_t ops = 0;
      interleave(tr, pts, 0.35, seed * 31 + 7, [&] {
        if (++ops == 1500) tr.check();  // once midway
      });
      require_valid(tr.t);
      tr.check();
      // Then remove every other remaining insertion.
      for (std::size_t k = 0; k < tr.live.size(); ++k) tr.remove_at(k);
      require_valid(tr.t);
      tr.check();
    }
  }
}

TEST_CASE("generated streams with removals equal CGAL", "[remove]") {
  for (pdt::Distribution d : {pdt::Distribution::uniform, pdt::Distribution::grid, pdt::Distribution::sphere}) {
    for (pdt::RemovalOrder order : {pdt::RemovalOrder::after, pdt::RemovalOrder::interleaved}) {
      INFO("distribution " << pdt::to_string(d) << ", order " << int(order));
      pdt::GenerateOptions o;
      o.dist = d;
      o.points = 3000;
      o.remove_fraction = 0.3;
      o.removal_order = order;
      o.seed = 9;
      pdt::OpStream s = pdt::generate(o);
      REQUIRE(s.insert_count() == 3000);
      REQUIRE(s.remove_count() == 900);
      pdt::Triangulation t;
      std::vector<pdt::VertexId> ids;
      std::vector<Point3> inserted;
      std::vector<char> undone;
      for (const auto& op : s.ops) {
        if (op.kind == pdt::Operation::Kind::insert) {
          ids.push_back(t.insert(op.point).vertex);
          inserted.push_back(op.point);
          undone.push_back(0);
        } else {
          REQUIRE(op.target < ids.size());
          REQUIRE_FALSE(undone[op.target]);
          undone[op.target] = 1;
          t.remove(ids[op.target]);
        }
      }
      std::vector<Point3> survivors;
      for (std::size_t k = 0; k < inserted.size(); ++k)
        if (!undone[k]) survivors.push_back(inserted[k]);
      require_valid(t);
      require_same_as_cgal(t, survivors);
    }
  }
}

TEST_CASE("removing 10%, 50% and 100% of the points", "[remove]") {
  struct Set {
    const char* name;
    std::vector<Point3> pts;
  };
  std::vector<Point3> lat = lattice(11);
  shuffle(lat, 3);
  std::vector<Point3> sph = cospherical(2025);
  shuffle(sph, 4);
  const Set sets[] = {{"uniform", random_points(3000, 81)}, {"lattice 11^3", lat}, {"sphere R^2=2025", sph}};
  for (const Set& s : sets) {
    for (double f : {0.1, 0.5, 1.0}) {
      for (bool random_order : {false, true}) {
        INFO(s.name << ", fraction " << f << (random_order ? ", random order" : ", insertion order"));
        Tracked tr;
        for (const auto& p : s.pts) tr.insert(p);
        const std::size_t n = static_cast<std::size_t>(f * s.pts.size());
        std::mt19937_64 rng(82);
        for (std::size_t k = 0; k < n; ++k) {
          if (random_order)
            tr.remove_at(rng() % tr.live.size());
          else
            tr.remove_at(0, true);  // the first inserted first
        }
        require_valid(tr.t);
        tr.check();
        if (f == 1.0) {
          REQUIRE(tr.t.number_of_vertices() == 0);
          REQUIRE(tr.t.dimension() == -1);
          REQUIRE(tr.t.number_of_cells() == 0);
          REQUIRE(tr.t.vertices().empty());
          // And build again.
          for (const auto& p : random_points(200, 83)) tr.insert(p);
          require_valid(tr.t);
          tr.check();
        }
      }
    }
  }
}

TEST_CASE("small cases: valid and equal to CGAL after every operation", "[remove][small]") {
  std::vector<Point3> lat = lattice(5);
  shuffle(lat, 5);
  std::vector<Point3> sph = cospherical(50);
  shuffle(sph, 6);
  std::vector<Point3> sph2 = cospherical(325);
  shuffle(sph2, 7);
  struct Set {
    const char* name;
    std::vector<Point3> pts;
  };
  const Set sets[] = {
      {"uniform", random_points(150, 91)},
      {"normal", generated_points(pdt::Distribution::normal, 150, 92)},
      {"line", generated_points(pdt::Distribution::line, 150, 93)},
      {"lattice 5^3", lat},
      {"sphere R^2=50", sph},
      {"sphere R^2=325", sph2},
      {"generated grid", generated_points(pdt::Distribution::grid, 150, 94)},
      {"generated sphere", generated_points(pdt::Distribution::sphere, 150, 95)},
  };
  for (const Set& s : sets) {
    for (std::uint64_t seed : {1, 2, 3}) {
      INFO(s.name << ", seed " << seed);
      Tracked tr;
      tr.keep_log = true;
      auto after = [&] {
        std::string why;
        const bool ok = tr.t.validate(&why);
        if (!ok) {
          std::string ops;
          for (const auto& l : tr.log) ops += l + "\n";
          INFO("operations:\n" << ops);
          INFO("validate: " << why);
          REQUIRE(ok);
        }
        tr.check();
      };
      interleave(tr, s.pts, 0.4, seed, after);
      // Remove everything, checking each step.
      std::mt19937_64 rng(seed);
      while (!tr.live.empty()) {
        tr.remove_at(rng() % tr.live.size());
        after();
      }
      REQUIRE(tr.t.dimension() == -1);
    }
  }
}

TEST_CASE("insert then remove the same point gives back the same triangulation", "[remove]") {
  auto run = [](std::vector<Point3> base, const std::vector<Point3>& probes) {
    pdt::Triangulation t;
    insert_all(t, base);
    std::vector<Point3> all = base;
    all.insert(all.end(), probes.begin(), probes.end());
    const PointIndex index = make_point_index(all);
    const Snapshot before = snapshot(t, index);
    for (const auto& q : probes) {
      INFO("probe " << str(q));
      auto r = t.insert(q);
      REQUIRE(t.is_vertex(r.vertex));
      auto rr = t.remove(r.vertex);
      REQUIRE(rr == (r.inserted ? pdt::RemoveResult::removed : pdt::RemoveResult::multiplicity_lowered));
      require_unchanged(t, index, before);
    }
    require_valid(t);
    require_same_as_cgal(t, base);
  };
  SECTION("uniform points; probes inside, outside, duplicates") {
    std::vector<Point3> base = random_points(800, 101);
    std::vector<Point3> probes = random_points(150, 102, -0.3, 1.3);
    for (int k = 0; k < 20; ++k) probes.push_back(base[k * 17]);
    probes.push_back({100, 100, 100});
    probes.push_back({-1e6, 0.5, 0.5});
    run(base, probes);
  }
  SECTION("lattice: probes on lattice points outside, half-integers, cospherical") {
    std::vector<Point3> base = lattice(6);
    shuffle(base, 103);
    std::vector<Point3> probes;
    std::mt19937_64 rng(104);
    for (int k = 0; k < 150; ++k)
      probes.push_back({double(rng() % 17) / 2 - 1.5, double(rng() % 17) / 2 - 1.5, double(rng() % 17) / 2 - 1.5});
    probes.push_back({2.5, 2.5, 2.5});
    probes.push_back({6, 6, 6});
    probes.push_back({-1, 2, 3});
    run(base, probes);
  }
  SECTION("510 cospherical points: the centre's link is all of them, put in spatial order") {
    std::vector<Point3> base = cospherical(2025);
    REQUIRE(base.size() >= pdt::Triangulation::Impl::large_link);
    shuffle(base, 107);
    run(base, {{0, 0, 0}, {1, 2, 3}, {-7, 4, 0}});
  }
  SECTION("cospherical set; probes at the centre and on the sphere's lattice") {
    std::vector<Point3> base = cospherical(325);
    std::vector<Point3> probes{{0, 0, 0}, {1, 0, 0}, {18, 1, 0}, {0, 0, 19}, {10, 10, 10}, {-18, 0, -1}};
    for (const auto& p : cospherical(50)) probes.push_back(p);
    run(base, probes);
  }
}

TEST_CASE("removal of hull vertices", "[remove]") {
  SECTION("cube corners") {
    Tracked tr;
    for (int x : {0, 1})
      for (int y : {0, 1})
        for (int z : {0, 1}) tr.insert({double(x), double(y), double(z)});
    for (const auto& p : random_points(150, 111, 0.2, 0.8)) tr.insert(p);
    // Points on the faces (cocircular with the corners).
    for (double a : {0.25, 0.5, 0.75}) {
      tr.insert({a, 0.5, 0});
      tr.insert({1, a, 0.5});
      tr.insert({0.5, 1, a});
    }
    tr.check();
    for (int k = 0; k < 8; ++k) {
      INFO("corner " << k);
      tr.remove_at(0, true);  // the first 8 live entries are the corners
      require_valid(tr.t);
      tr.check();
    }
  }
  SECTION("peeling the hull layer by layer") {
    Tracked tr;
    for (const auto& p : generated_points(pdt::Distribution::normal, 1500, 112)) tr.insert(p);
    for (int layer = 0; layer < 5 && tr.t.dimension() == 3; ++layer) {
      INFO("layer " << layer);
      auto hull = hull_vertices(tr.t);
      REQUIRE(hull.size() >= 4);
      std::set<pdt::VertexId> h(hull.begin(), hull.end());
      for (std::size_t k = 0; k < tr.live.size();)
        if (h.count(tr.live[k].v))
          tr.remove_at(k);
        else
          ++k;
      for (auto v : hull) REQUIRE_FALSE(tr.t.is_vertex(v));
      require_valid(tr.t);
      tr.check();
    }
  }
}

TEST_CASE("removal down to 4, 3, 0 vertices and back", "[remove][degenerate]") {
  Tracked tr;
  for (const auto& p : random_points(60, 121)) tr.insert(p);
  std::mt19937_64 rng(122);
  while (tr.live.size() > 4) tr.remove_at(rng() % tr.live.size());
  REQUIRE(tr.t.number_of_vertices() == 4);
  REQUIRE(tr.t.dimension() == 3);
  REQUIRE(tr.t.number_of_finite_cells() == 1);
  REQUIRE(tr.t.number_of_cells() == 5);
  require_valid(tr.t);
  tr.check();
  tr.remove_at(0);
  REQUIRE(tr.t.number_of_vertices() == 3);
  REQUIRE(tr.t.dimension() == 2);
  REQUIRE(tr.t.number_of_finite_cells() == 0);
  REQUIRE(tr.t.finite_cells().empty());
  require_valid(tr.t);
  tr.check();
  tr.remove_at(0);
  REQUIRE(tr.t.dimension() == 1);
  tr.remove_at(0);
  REQUIRE(tr.t.dimension() == 0);
  require_valid(tr.t);
  tr.remove_at(0);
  REQUIRE(tr.t.dimension() == -1);
  REQUIRE(tr.t.number_of_vertices() == 0);
  require_valid(tr.t);
  for (const auto& p : random_points(300, 123)) tr.insert(p);
  REQUIRE(tr.t.dimension() == 3);
  require_valid(tr.t);
  tr.check();
}

TEST_CASE("removal down to a coplanar, then collinear set, then back to 3D", "[remove][degenerate]") {
  Tracked tr;
  for (int x = 0; x < 10; ++x)
    for (int y = 0; y < 10; ++y) tr.insert({double(x), double(y), 0});
  const std::size_t n_plane = tr.live.size();
  for (const auto& p : random_points(40, 131, 0, 9)) tr.insert(p);
  REQUIRE(tr.t.dimension() == 3);
  tr.check();
  // Remove the off-plane points (live entries n_plane..; swap-pop from the back keeps order).
  while (tr.live.size() > n_plane) {
    tr.remove_at(tr.live.size() - 1);
    if (tr.live.size() > n_plane) REQUIRE(tr.t.dimension() == 3);
  }
  REQUIRE(tr.t.dimension() == 2);
  REQUIRE(tr.t.number_of_finite_cells() == 0);
  REQUIRE(tr.t.number_of_vertices() == 100);
  require_valid(tr.t);
  tr.check();
  // Back to 3D with integer points above and below: cospherical with the grid.
  for (int k = 0; k < 20; ++k) tr.insert({double(k % 9), double((k * 7) % 9), double(k % 2 ? 2 : -3)});
  REQUIRE(tr.t.dimension() == 3);
  require_valid(tr.t);
  tr.check();
  // Now remove everything but the row y == 0 of the plane: collinear.
  for (std::size_t k = 0; k < tr.live.size();)
    if (tr.live[k].p.y != 0 || tr.live[k].p.z != 0)
      tr.remove_at(k);
    else
      ++k;
  REQUIRE(tr.t.number_of_vertices() == 10);
  REQUIRE(tr.t.dimension() == 1);
  require_valid(tr.t);
  tr.insert({3, 5, 0});
  REQUIRE(tr.t.dimension() == 2);
  tr.insert({3, 5, 1});
  REQUIRE(tr.t.dimension() == 3);
  require_valid(tr.t);
  tr.check();
  for (const auto& p : random_points(50, 132, 0, 9)) tr.insert(p);
  require_valid(tr.t);
  tr.check();
}

TEST_CASE("cavities larger than a free list reuse the ids freed before: memory stays bounded", "[remove][memory]") {
  // The centre of 2496 cospherical points conflicts with every cell, and its
  // removal rebuilds them all: each toggle frees and takes thousands of cell
  // ids, more than a context's free list keeps (the rest waits in the spare
  // stack). Before, every such cavity took a fresh range of ids: the id range
  // (and memory_bytes) grew by the whole mesh per toggle.
  std::vector<Point3> sphere = cospherical(32045);
  REQUIRE(sphere.size() == 2496);
  shuffle(sphere, 109);
  pdt::Triangulation t;
  insert_all(t, sphere);
  auto toggle = [&] {
    const auto r = t.insert({0, 0, 0});
    REQUIRE(r.inserted);
    REQUIRE(t.remove(r.vertex) == pdt::RemoveResult::removed);
  };
  toggle();
  const std::size_t after_one = t.memory_bytes();
  for (int k = 0; k < 20; ++k) toggle();
  INFO("memory_bytes after 1 toggle " << after_one << ", after 21 " << t.memory_bytes());
  REQUIRE(t.memory_bytes() <= after_one + after_one / 4);
  require_valid(t);
  require_same_as_cgal(t, sphere);
}

TEST_CASE("multiplicity: insert twice, remove twice", "[remove]") {
  pdt::Triangulation t;
  std::vector<Point3> pts = random_points(200, 141);
  insert_all(t, pts);
  const Point3 p{0.5, 0.25, 0.125};
  pts.push_back(p);
  const PointIndex index = make_point_index(pts);
  auto a = t.insert(p);
  REQUIRE(a.inserted);
  const Snapshot with_p = snapshot(t, index);
  auto b = t.insert(p);
  REQUIRE_FALSE(b.inserted);
  REQUIRE(b.vertex == a.vertex);
  REQUIRE(t.multiplicity(a.vertex) == 2);
  REQUIRE(t.remove(a.vertex) == pdt::RemoveResult::multiplicity_lowered);
  REQUIRE(t.is_vertex(a.vertex));
  REQUIRE(t.multiplicity(a.vertex) == 1);
  require_unchanged(t, index, with_p);
  REQUIRE(t.remove(a.vertex) == pdt::RemoveResult::removed);
  REQUIRE_FALSE(t.is_vertex(a.vertex));
  REQUIRE(t.multiplicity(a.vertex) == 0);
  REQUIRE(t.number_of_vertices() == 200);
  require_valid(t);
  pts.pop_back();
  require_same_as_cgal(t, pts);
  SECTION("in lower dimension") {
    pdt::Triangulation u;
    auto v = u.insert({1, 2, 3}).vertex;
    u.insert({1, 2, 3});
    u.insert({4, 5, 6});
    REQUIRE(u.remove(v) == pdt::RemoveResult::multiplicity_lowered);
    REQUIRE(u.dimension() == 1);
    REQUIRE(u.remove(v) == pdt::RemoveResult::removed);
    REQUIRE(u.dimension() == 0);
    REQUIRE(u.number_of_vertices() == 1);
  }
}

TEST_CASE("bad removals throw unknown_vertex and change nothing", "[remove][error]") {
  auto expect_unknown = [](pdt::Triangulation& t, pdt::VertexId v, const PointIndex& index) {
    INFO("remove(" << v << ")");
    const Snapshot before = snapshot(t, index);
    const auto stats = t.stats();
    bool threw = false;
    try {
      t.remove(v);
    } catch (const pdt::Error& e) {
      threw = true;
      REQUIRE(e.code() == pdt::ErrorCode::unknown_vertex);
      REQUIRE(std::string(e.what()).size() > 0);
    }
    REQUIRE(threw);
    require_unchanged(t, index, before);
    REQUIRE(t.stats().removals == stats.removals);
    require_valid(t);
  };
  auto all_bad = [&](pdt::Triangulation& t, const std::vector<Point3>& pts) {
    const PointIndex index = make_point_index(pts);
    expect_unknown(t, pdt::infinite_vertex, index);
    expect_unknown(t, t.vertex_id_bound(), index);
    expect_unknown(t, t.vertex_id_bound() + 1000, index);
    expect_unknown(t, 0x7FFFFFFFu, index);
    expect_unknown(t, pdt::no_vertex, index);
  };
  SECTION("empty") {
    pdt::Triangulation t;
    all_bad(t, {});
    pdt::Triangulation u;
    expect_unknown(u, 1, {});
  }
  SECTION("dimension 1 and 2") {
    pdt::Triangulation t;
    std::vector<Point3> pts{{0, 0, 0}, {1, 1, 0}};
    auto ids = insert_all(t, pts);
    all_bad(t, pts);
    t.remove(ids[1]);
    expect_unknown(t, ids[1], make_point_index(pts));
    pts.push_back({1, 0, 0});
    pts.push_back({0, 1, 0});
    insert_all(t, pts);
    REQUIRE(t.dimension() == 2);
    all_bad(t, pts);
  }
  SECTION("dimension 3") {
    pdt::Triangulation t;
    std::vector<Point3> pts = random_points(300, 151);
    auto ids = insert_all(t, pts);
    all_bad(t, pts);
    // Removed twice.
    REQUIRE(t.remove(ids[10]) == pdt::RemoveResult::removed);
    expect_unknown(t, ids[10], make_point_index(pts));
    // Removed with multiplicity: the third removal fails.
    t.insert(pts[20]);
    REQUIRE(t.remove(ids[20]) == pdt::RemoveResult::multiplicity_lowered);
    REQUIRE(t.remove(ids[20]) == pdt::RemoveResult::removed);
    expect_unknown(t, ids[20], make_point_index(pts));
    // The triangulation is still right.
    std::vector<Point3> survivors;
    for (std::size_t k = 0; k < pts.size(); ++k)
      if (k != 10 && k != 20) survivors.push_back(pts[k]);
    require_same_as_cgal(t, survivors);
  }
}

TEST_CASE("real point sets: remove a random half", "[remove][real]") {
  struct Case {
    const char* file;
    std::size_t max_points;
  };
  const Case cases[] = {
      {"scans/cgal_b9.ply", 0},
      {"degenerate/cgal_radar.xyz", 0},
      {"scans/stanford_bunny_bun000.ply", 20000},
  };
  for (const Case& c : cases) {
    const std::string path = shared_data(c.file);
    if (!std::filesystem::exists(path)) {
      WARN("data file absent, skipped: " << path);
      continue;
    }
    INFO("file " << c.file);
    std::vector<Point3> pts = pdt::read_points(path);
    if (c.max_points && pts.size() > c.max_points) pts.resize(c.max_points);
    Tracked tr;
    for (const auto& p : pts) tr.insert(p);
    std::mt19937_64 rng(161);
    const std::size_t n = tr.live.size() / 2;
    for (std::size_t k = 0; k < n; ++k) tr.remove_at(rng() % tr.live.size());
    require_valid(tr.t);
    tr.check();
  }
}

TEST_CASE("removal of a vertex whose link is flat", "[remove][degenerate]") {
  // A 4x4x4 lattice with a point just above the centre of each face: each
  // such apex sees only the (coplanar) face points, so the hole left by its
  // removal is closed by the hull facets alone.
  Tracked tr;
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z) tr.insert({double(x), double(y), double(z)});
  const std::size_t n_lattice = tr.live.size();
  const Point3 apexes[] = {{1.5, 1.5, 3.25}, {1.5, 1.5, -0.25}, {1.5, 3.5, 1.5},
                           {1.5, -0.5, 1.5}, {4, 1.5, 1.5},     {-1, 1.5, 1.5}};
  for (const auto& a : apexes) tr.insert(a);
  require_valid(tr.t);
  tr.check();
  while (tr.live.size() > n_lattice) {
    tr.remove_at(tr.live.size() - 1);
    require_valid(tr.t);
    tr.check();
  }
  // And the square pyramid: its apex removed leaves a coplanar set.
  Tracked pyr;
  for (int x = 0; x < 3; ++x)
    for (int y = 0; y < 3; ++y) pyr.insert({double(x), double(y), 0});
  pyr.insert({1, 1, 1});
  REQUIRE(pyr.t.dimension() == 3);
  pyr.remove_at(pyr.live.size() - 1);
  REQUIRE(pyr.t.dimension() == 2);
  require_valid(pyr.t);
  pyr.insert({1, 1, -1});
  REQUIRE(pyr.t.dimension() == 3);
  require_valid(pyr.t);
  pyr.check();
}

TEST_CASE("removal with extreme but finite coordinates", "[remove][extreme]") {
  auto run = [](double scale, double offset) {
    std::vector<Point3> pts = random_points(400, 221, -1, 1);
    for (auto& p : pts) p = {offset + p.x * scale, offset + p.y * scale, offset + p.z * scale};
    Tracked tr;
    for (const auto& p : pts) tr.insert(p);
    std::mt19937_64 rng(222);
    for (int k = 0; k < 200; ++k) tr.remove_at(rng() % tr.live.size());
    require_valid(tr.t);
    tr.check();
  };
  SECTION("magnitude 1e300") { run(1e300, 0); }
  SECTION("magnitude 1e-300") { run(1e-300, 0); }
  SECTION("large offset, small extent") { run(1e-3, 1e9); }
  SECTION("subnormal") { run(1e-310, 0); }
  SECTION("the largest doubles") { run(std::numeric_limits<double>::max(), 0); }
}

TEST_CASE("a cell id at its last incarnation is retired, never wrapped to a repeated handle", "[remove][handles]") {
  // Cell incarnations are 30 bits: 2^30 reuses of one id would wrap. Push every
  // id of a mesh to the incarnation before retire_at, then churn: each id is
  // made once more (at retire_at) and, when that cell dies, retired.
  std::vector<Point3> pts = generated_points(pdt::Distribution::uniform, 300, 5);
  pdt::Triangulation t;
  std::vector<pdt::VertexId> vs;
  for (const Point3& p : pts) vs.push_back(t.insert(p).vertex);
  auto& impl = pdt::detail::impl_of(t);
  using Impl = std::remove_reference_t<decltype(impl)>;
  constexpr std::uint32_t retire_at = Impl::retire_at;
  const pdt::CellId preset = t.cell_id_bound();
  std::vector<bool> aged(preset, false);
  for (pdt::CellId c = 0; c < preset; ++c)  // a free id stays marked free, a never used one (tag 0) unused
    if (impl.tags[c].load() != 0) {
      impl.tags[c].store(((retire_at - 1) << 2) | (impl.tags[c].load() & 3));
      aged[c] = true;
    }
  require_valid(t);  // I8 still holds
  std::map<std::pair<pdt::CellId, std::uint32_t>, std::array<pdt::VertexId, 4>> seen;  // handle -> its cell
  std::vector<pdt::CellHandle> at_retire;
  auto look = [&] {
    for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
      if (!t.is_cell(c)) continue;
      const pdt::CellHandle h = t.cell_handle(c);
      if (c < preset && aged[c]) REQUIRE(h.incarnation >= retire_at - 1);  // never wrapped to a small one
      std::array<pdt::VertexId, 4> v{t.cell_vertex(c, 0), t.cell_vertex(c, 1), t.cell_vertex(c, 2), t.cell_vertex(c, 3)};
      std::sort(v.begin(), v.end());
      auto [it, fresh] = seen.emplace(std::pair{c, h.incarnation}, v);
      REQUIRE(it->second == v);  // one (id, incarnation), one cell
      if (fresh && h.incarnation == retire_at) at_retire.push_back(h);
    }
  };
  std::mt19937_64 rng(9);
  for (int round = 0; round < 400; ++round) {
    const std::size_t k = rng() % pts.size();
    t.remove(vs[k]);
    vs[k] = t.insert(pts[k]).vertex;
    look();
  }
  CHECK(at_retire.size() > 100);
  std::size_t dead = 0;
  for (const pdt::CellHandle& h : at_retire) {
    const bool gone = !t.cell(h).has_value();
    dead += gone;
    if (gone) CHECK_FALSE(t.is_cell(h.id));  // retired: that id is never made again
  }
  CHECK(dead > 50);  // those cells died: their ids were retired, not renewed
  CHECK(t.cell_id_bound() > preset);
  require_valid(t);
  REQUIRE(canonical_tets(t, pts) == cgal_tets(pts));
}

TEST_CASE("a cell renewed in place at retire_at (a hull vertex with a flat link removed) does not wrap",
          "[remove][handles]") {
  // Points on the plane z = 0, one far below (the triangulation is 3D) and an
  // apex just above: the apex's finite link lies in the plane, so its
  // removal turns its finite cells into infinite ones in place
  // (fill_hole_flat_link), each a renewal on top of the allocation that made
  // it. At retire_at, that takes it to the last incarnation, not to 0.
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts;
  for (int i = 0; i < 60; ++i) pts.push_back({u(rng), u(rng), 0});
  pts.push_back({0.5, 0.5, -10});
  pdt::Triangulation t;
  for (const Point3& p : pts) (void)t.insert(p);
  const pdt::VertexId apex = t.insert({0.5, 0.5, 0.05}).vertex;
  auto& impl = pdt::detail::impl_of(t);
  using Impl = std::remove_reference_t<decltype(impl)>;
  std::vector<pdt::CellId> apex_cells;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
    if (!t.is_cell(c)) continue;
    impl.tags[c].store(Impl::retire_at << 2);  // as if allocated 2^30 - 2 times
    for (int i = 0; i < 4; ++i)
      if (t.cell_vertex(c, i) == apex && t.is_finite_cell(c)) apex_cells.push_back(c);
  }
  impl.some_id_retiring.store(true);
  REQUIRE(apex_cells.size() >= 3);
  t.remove(apex);
  require_valid(t);
  std::size_t renewed = 0;
  for (pdt::CellId c : apex_cells)
    if (t.is_cell(c)) {  // kept in place, now infinite
      const pdt::CellHandle h = t.cell_handle(c);
      CHECK(h.incarnation == Impl::last_incarnation);
      CHECK(t.cell(h).has_value());
      ++renewed;
    }
  CHECK(renewed >= 3);
  // The apex again: those cells die, and their ids retire.
  (void)t.insert({0.5, 0.5, 0.05});
  for (pdt::CellId c : apex_cells) CHECK_FALSE(t.is_cell(c));
  require_valid(t);
  pts.push_back({0.5, 0.5, 0.05});
  REQUIRE(canonical_tets(t, pts) == cgal_tets(pts));
}

TEST_CASE("after a huge cavity and its removal, the context keeps no more scratch than scratch_kept", "[remove][memory]") {
  // A point at the centre of 3000 exactly cospherical points conflicts with
  // every cell; removing it triangulates a link of all 3000. The scratch that
  // took (and the link triangulation) is freed afterwards: a context's memory
  // follows the live mesh, not the largest operation it met (with 16 engine
  // workers that each met one, 270 MB against a 13 MB mesh before).
  const std::vector<Point3> pts = generated_points(pdt::Distribution::sphere, 3000, 1);
  pdt::Triangulation t;
  t.insert_batch(pts);
  auto& impl = pdt::detail::impl_of(t);
  using Context = std::remove_reference_t<decltype(*impl.seq)>;
  constexpr std::size_t kept = Context::scratch_kept;
  std::size_t zone_during = 0, views_during = 0, link_cells_during = 0;
  t.set_change_hook([&](const pdt::Changes& c) {  // inside the operation: its scratch in use
    zone_during = std::max(zone_during, impl.seq->conflict_zone.capacity());
    views_during = std::max(views_during, c.created.size());
    if (impl.seq->small) link_cells_during = std::max<std::size_t>(link_cells_during, impl.seq->small->cells.size());
  });
  const pdt::InsertResult centre = t.insert({0, 0, 0});
  REQUIRE(centre.inserted);
  INFO("conflict zone " << zone_during << ", cells made " << views_during);
  REQUIRE(zone_during > kept);  // the operation did need more than is kept
  CHECK(impl.seq->conflict_zone.capacity() <= kept);
  CHECK(impl.seq->boundary.capacity() <= kept);
  CHECK(impl.seq->created.capacity() <= kept);
  CHECK(impl.seq->views.capacity() <= kept);
  t.remove(centre.vertex);
  INFO("link triangulation cells " << link_cells_during);
  REQUIRE(link_cells_during > kept);
  CHECK(impl.seq->small == nullptr);
  CHECK(impl.seq->hole.capacity() <= kept);
  CHECK(impl.seq->small_facet_boundary.capacity() <= kept);
  // And the next huge operation makes them again, with the same result.
  t.set_change_hook(nullptr);
  const pdt::VertexId again = t.insert({0, 0, 0}).vertex;
  CHECK(t.remove(again) == pdt::RemoveResult::removed);
  require_valid(t);
  CHECK(t.number_of_vertices() == pts.size());
}
