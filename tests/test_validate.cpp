// SPDX-License-Identifier: MIT
// validate(): true on good triangulations of every kind; false, with a
// message, once the structure is deliberately corrupted through impl().
#include <algorithm>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "common/cgal_reference.hpp"
#include "pdt/triangulation.hpp"
#include "triangulation_impl.hpp"

using namespace pdt_test;
using pdt::Point3;

namespace {

// REQUIREs validate() false with a non-empty message (and false without one too).
void require_invalid(const pdt::Triangulation& t) {
  std::string why;
  const bool ok = t.validate(&why);
  REQUIRE_FALSE(ok);
  INFO("message: " << why);
  REQUIRE_FALSE(why.empty());
  REQUIRE_FALSE(t.validate());
}

pdt::CellId first_cell(const pdt::Triangulation& t, bool finite, pdt::CellId from = 0) {
  for (pdt::CellId c = from; c < t.cell_id_bound(); ++c)
    if (t.is_cell(c) && t.is_finite_cell(c) == finite) return c;
  return pdt::no_cell;
}

// A finite cell with a finite neighbour across facet i (returned through i).
pdt::CellId interior_facet_cell(const pdt::Triangulation& t, int* i) {
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
    if (!t.is_cell(c) || !t.is_finite_cell(c)) continue;
    for (int k = 0; k < 4; ++k)
      if (t.is_finite_cell(t.cell_neighbor(c, k))) {
        *i = k;
        return c;
      }
  }
  return pdt::no_cell;
}

bool cell_has(const pdt::Triangulation& t, pdt::CellId c, pdt::VertexId v) {
  for (int i = 0; i < 4; ++i)
    if (t.cell_vertex(c, i) == v) return true;
  return false;
}

pdt::Triangulation random_triangulation(std::size_t n, std::uint64_t seed) {
  pdt::Triangulation t;
  insert_all(t, random_points(n, seed));
  return t;
}

}  // namespace

TEST_CASE("validate accepts good triangulations", "[validate]") {
  pdt::Triangulation t;
  require_valid(t);
  t.insert({0, 0, 0});
  require_valid(t);
  t.insert({1, 0, 0});
  require_valid(t);
  t.insert({0, 1, 0});
  require_valid(t);
  t.insert({0, 0, 1});
  require_valid(t);
  insert_all(t, random_points(500, 1));
  require_valid(t);
  for (auto v : t.vertices())
    if (v % 3 == 0) t.remove(v);
  require_valid(t);
  pdt::Triangulation lat;
  for (int x = 0; x < 5; ++x)
    for (int y = 0; y < 5; ++y)
      for (int z = 0; z < 5; ++z) lat.insert({double(x), double(y), double(z)});
  require_valid(lat);
  // validate() does not change anything.
  const TetList before = canonical_tets(lat, surviving_points(lat));
  REQUIRE(lat.validate());
  REQUIRE((canonical_tets(lat, surviving_points(lat)) == before));
}

TEST_CASE("validate's edge count (Euler) is the same in one pass or many", "[validate]") {
  // The distinct edges, counted in passes over ranges of their lower vertex
  // id: any number of passes gives the count a set of all the edges gives,
  // which for a triangulation of the sphere is V + C (with the infinite vertex).
  pdt::Triangulation t = random_triangulation(3000, 11);
  for (auto v : t.vertices())
    if (v % 5 == 0) t.remove(v);  // free ids among the live ones
  std::set<std::pair<pdt::VertexId, pdt::VertexId>> edges;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
    if (!t.is_cell(c)) continue;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) edges.insert(std::minmax(t.cell_vertex(c, i), t.cell_vertex(c, j)));
  }
  CHECK(edges.size() == t.number_of_vertices() + 1 + t.number_of_cells());
  const auto& m = pdt::detail::impl_of(t);
  for (std::size_t pass_edges : {std::size_t{1} << 30, std::size_t{5000}, std::size_t{977}}) {
    INFO("about " << pass_edges << " edges a pass");
    CHECK(m.count_distinct_edges(pass_edges) == edges.size());
  }
  require_valid(t);
}

TEST_CASE("validate detects a wrongly oriented cell", "[validate]") {
  pdt::Triangulation t = random_triangulation(200, 2);
  require_valid(t);
  auto& cells = pdt::detail::impl_of(t).cells;
  SECTION("finite cell: two vertices swapped") {
    pdt::CellId c = first_cell(t, true);
    REQUIRE(c != pdt::no_cell);
    std::swap(cells[c].v[0], cells[c].v[1]);
    require_invalid(t);
    std::swap(cells[c].v[0], cells[c].v[1]);
    require_valid(t);
  }
  SECTION("finite cell: two vertices and their neighbours swapped consistently") {
    // Adjacency stays consistent from this side; only the orientation is wrong
    // (and the facets are seen with the wrong handedness).
    pdt::CellId c = first_cell(t, true);
    std::swap(cells[c].v[2], cells[c].v[3]);
    std::swap(cells[c].n[2], cells[c].n[3]);
    require_invalid(t);
  }
  SECTION("infinite cell: two finite vertices swapped") {
    pdt::CellId c = first_cell(t, false);
    REQUIRE(c != pdt::no_cell);
    int a = -1, b = -1;
    for (int i = 0; i < 4; ++i)
      if (cells[c].v[i] != pdt::infinite_vertex) (a < 0 ? a : b) = i;
    std::swap(cells[c].v[a], cells[c].v[b]);
    require_invalid(t);
  }
}

TEST_CASE("validate detects broken adjacency", "[validate]") {
  pdt::Triangulation t = random_triangulation(200, 3);
  auto& cells = pdt::detail::impl_of(t).cells;
  int i = -1;
  pdt::CellId c = interior_facet_cell(t, &i);
  REQUIRE(c != pdt::no_cell);
  const std::uint32_t saved = cells[c].n[i];
  SECTION("a neighbour link to an unrelated cell") {
    pdt::CellId d = pdt::no_cell;
    for (pdt::CellId x = 0; x < t.cell_id_bound(); ++x) {
      bool adjacent = false;
      for (int k = 0; k < 4; ++k) adjacent |= t.cell_neighbor(c, k) == x;
      if (t.is_cell(x) && x != c && !adjacent) {
        d = x;
        break;
      }
    }
    REQUIRE(d != pdt::no_cell);
    cells[c].n[i] = 4 * d + (saved & 3u);
    require_invalid(t);
    cells[c].n[i] = saved;
    require_valid(t);
  }
  SECTION("the right neighbour but the wrong mirror facet") {
    cells[c].n[i] = (saved & ~3u) | ((saved + 1) & 3u);
    require_invalid(t);
  }
  SECTION("a back-link broken on the other side") {
    const pdt::CellId d = saved >> 2;
    const int j = static_cast<int>(saved & 3u);
    const std::uint32_t other = cells[d].n[j];
    REQUIRE(other == 4 * c + static_cast<std::uint32_t>(i));
    cells[d].n[j] = 4 * d + static_cast<std::uint32_t>(j);  // points at itself
    require_invalid(t);
    cells[d].n[j] = other;
    require_valid(t);
  }
  SECTION("a cell with a repeated vertex") {
    const pdt::VertexId saved_v = cells[c].v[1];
    cells[c].v[1] = cells[c].v[0];
    require_invalid(t);
    cells[c].v[1] = saved_v;
    require_valid(t);
  }
  SECTION("a cell naming a dead vertex") {
    const pdt::VertexId saved_v = cells[c].v[2];
    cells[c].v[2] = t.vertex_id_bound() + 5;
    require_invalid(t);
    cells[c].v[2] = saved_v;
    require_valid(t);
  }
}

TEST_CASE("validate detects a wrong vertex-to-cell link", "[validate]") {
  pdt::Triangulation t = random_triangulation(200, 4);
  auto& verts = pdt::detail::impl_of(t).verts;
  const pdt::VertexId v = t.vertices()[7];
  const pdt::CellId saved = verts[v].cell;
  REQUIRE(cell_has(t, saved, v));
  SECTION("incident cell does not contain the vertex") {
    pdt::CellId other = pdt::no_cell;
    for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c)
      if (t.is_cell(c) && !cell_has(t, c, v)) {
        other = c;
        break;
      }
    REQUIRE(other != pdt::no_cell);
    verts[v].cell = other;
    require_invalid(t);
    verts[v].cell = saved;
    require_valid(t);
  }
  SECTION("incident cell is not a cell") {
    verts[v].cell = pdt::no_cell;
    require_invalid(t);
  }
  SECTION("a live vertex with multiplicity 0") {
    verts[v].multiplicity = 0;
    require_invalid(t);
  }
}

TEST_CASE("validate detects a cell mark out of place: a live cell marked, a free id not marked free", "[validate]") {
  // I7 and I8 (triangulation_impl.hpp): a cell handle is read from the tag.
  pdt::Triangulation t = random_triangulation(200, 6);
  for (int k = 0; k < 20; ++k) t.remove(t.vertices()[static_cast<std::size_t>(3 * k)]);  // some ids freed
  auto& m = pdt::detail::impl_of(t);
  pdt::CellId live = pdt::no_cell, free = pdt::no_cell;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c)
    if (t.is_cell(c))
      live = c;
    else if (m.tags[c].load() != 0)  // once allocated (a fresh id's tag is 0)
      free = c;
  REQUIRE(live != pdt::no_cell);
  REQUIRE(free != pdt::no_cell);
  REQUIRE((m.tags[free].load() & 3) == 3);  // freed: marked so
  require_valid(t);
  SECTION("a live cell still marked by a search") {
    m.tags[live].fetch_or(1);
    require_invalid(t);
    m.tags[live].fetch_and(~3u);
    require_valid(t);
  }
  SECTION("a free id whose tag reads as a live incarnation") {
    m.tags[free].fetch_and(~3u);
    require_invalid(t);
    m.tags[free].fetch_or(3);
    require_valid(t);
  }
}

TEST_CASE("validate detects a facet that is not locally Delaunay", "[validate]") {
  using KPoint = pdt::Triangulation::Impl::KPoint;
  SECTION("bipyramid: apex moved inside the other tetrahedron's circumsphere") {
    // Base triangle abc, apexes d above and e below. sphere(abcd) has centre
    // (0.5, 0.5, 0.29), radius^2 0.5841; e = (0.3, 0.3, -1) is outside it, so the
    // triangulation is the two tetrahedra abcd, abce.
    pdt::Triangulation t;
    t.insert({0, 0, 0});
    t.insert({1, 0, 0});
    t.insert({0, 1, 0});
    t.insert({0.3, 0.3, 1});
    const pdt::VertexId e = t.insert({0.3, 0.3, -1}).vertex;
    REQUIRE(t.number_of_finite_cells() == 2);
    require_valid(t);
    // Moved to (0.3, 0.3, -0.01): still below the base (every orientation and
    // the convexity of the hull are unchanged) but at squared distance 0.17 from
    // the centre: inside sphere(abcd). Only the Delaunay property fails.
    pdt::detail::impl_of(t).verts[e].p = KPoint(0.3, 0.3, -0.01);
    REQUIRE(all_positively_oriented(t));
    require_invalid(t);
    pdt::detail::impl_of(t).verts[e].p = KPoint(0.3, 0.3, -1);
    require_valid(t);
  }
  SECTION("random triangulation: a vertex moved next to an opposite facet") {
    pdt::Triangulation t = random_triangulation(300, 5);
    int i = -1;
    pdt::CellId c = interior_facet_cell(t, &i);
    REQUIRE(c != pdt::no_cell);
    // Move the vertex opposite facet i of the neighbour close to the centroid
    // of the shared facet, on its own side: inside c's circumsphere.
    const pdt::CellId d = t.cell_neighbor(c, i);
    pdt::VertexId w = pdt::no_vertex;
    for (int k = 0; k < 4; ++k)
      if (!cell_has(t, c, t.cell_vertex(d, k))) w = t.cell_vertex(d, k);
    REQUIRE(w != pdt::no_vertex);
    Point3 g{0, 0, 0};
    for (int k = 0; k < 4; ++k)
      if (k != i) {
        Point3 p = t.point(t.cell_vertex(c, k));
        g = {g.x + p.x / 3, g.y + p.y / 3, g.z + p.z / 3};
      }
    const Point3 old = t.point(w);
    const double s = 1e-3;
    pdt::detail::impl_of(t).verts[w].p = KPoint(g.x + s * (old.x - g.x), g.y + s * (old.y - g.y), g.z + s * (old.z - g.z));
    require_invalid(t);
    pdt::detail::impl_of(t).verts[w].p = KPoint(old.x, old.y, old.z);
    require_valid(t);
  }
  SECTION("lattice: a vertex moved onto another vertex") {
    pdt::Triangulation t;
    for (int x = 0; x < 4; ++x)
      for (int y = 0; y < 4; ++y)
        for (int z = 0; z < 4; ++z) t.insert({double(x), double(y), double(z)});
    require_valid(t);
    const pdt::VertexId v = t.locate({1, 1, 1}).vertex;
    REQUIRE(t.is_vertex(v));
    pdt::detail::impl_of(t).verts[v].p = KPoint(1, 1, 2);
    require_invalid(t);
  }
}

TEST_CASE("validate checks lower-dimensional states", "[validate]") {
  using KPoint = pdt::Triangulation::Impl::KPoint;
  pdt::Triangulation t;
  for (int x = 0; x < 5; ++x)
    for (int y = 0; y < 5; ++y) t.insert({double(x), double(y), 0});
  REQUIRE(t.dimension() == 2);
  require_valid(t);
  SECTION("a vertex moved off the plane") {
    const pdt::VertexId v = t.vertices()[12];
    pdt::detail::impl_of(t).verts[v].p = KPoint(2, 2, 1);
    require_invalid(t);
  }
  SECTION("a live vertex with multiplicity 0") {
    const pdt::VertexId v = t.vertices()[3];
    pdt::detail::impl_of(t).verts[v].multiplicity = 0;
    require_invalid(t);
  }
}
