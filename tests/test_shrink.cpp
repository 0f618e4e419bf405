// SPDX-License-Identifier: MIT
// Triangulation::shrink_to_fit: after removals it gives the freed storage
// back, leaves the same triangulation, keeps every vertex id and handle, and
// no cell handle ever names another cell; later insertions (sequential or an
// engine's) reuse what was given back and still equal CGAL.
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <set>
#include <string>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/engine_run.hpp"
#include "id_ranges.hpp"
#include "triangulation_impl.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/triangulation.hpp"

using namespace pdt_test;
using pdt::Point3;

namespace {

const pdt::Box kUnit{{0, 0, 0}, {1, 1, 1}};

using Quad = std::array<pdt::VertexId, 4>;

Quad sorted_vertices(const pdt::Triangulation& t, pdt::CellId c) {
  Quad q{t.cell_vertex(c, 0), t.cell_vertex(c, 1), t.cell_vertex(c, 2), t.cell_vertex(c, 3)};
  std::sort(q.begin(), q.end());
  return q;
}

std::set<Quad> cell_set(const pdt::Triangulation& t) {
  std::set<Quad> s;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c)
    if (t.is_cell(c)) s.insert(sorted_vertices(t, c));
  return s;
}

Quad view_vertices(const pdt::CellView& v) {
  Quad q = v.vertices;
  std::sort(q.begin(), q.end());
  return q;
}

// Every live cell's handle, with its vertices.
std::vector<std::pair<pdt::CellHandle, Quad>> all_handles(const pdt::Triangulation& t) {
  std::vector<std::pair<pdt::CellHandle, Quad>> hs;
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c)
    if (t.is_cell(c)) hs.emplace_back(t.cell_handle(c), sorted_vertices(t, c));
  return hs;
}

}  // namespace

TEST_CASE("shrink_to_fit gives back the storage of removed vertices and keeps the triangulation", "[shrink]") {
  const std::vector<Point3> pts = random_points(60000, 71);
  pdt::Triangulation t;
  const std::vector<pdt::InsertResult> in = t.insert_batch(pts);
  // Survivors: every 1000th vertex id (long runs of free ids between them,
  // whose records can go) and 300 more at random (short runs, which stay).
  std::vector<char> keep(pts.size(), 0);
  for (std::size_t i = 0; i < pts.size(); ++i) keep[i] = in[i].vertex % 1000 == 0;
  std::vector<std::size_t> order(pts.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  shuffle(order, 72);
  for (std::size_t k = 0; k < 300; ++k) keep[order[k]] = 1;
  std::vector<pdt::VertexHandle> handles(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) handles[i] = t.vertex_handle(in[i].vertex);
  std::vector<Point3> survivors;
  for (std::size_t i : order) {
    if (keep[i])
      survivors.push_back(pts[i]);
    else
      t.remove(in[i].vertex);
  }
  const std::size_t bytes_before = t.memory_bytes();
  const std::set<Quad> cells_before = cell_set(t);
  const auto handles_before = all_handles(t);
  const pdt::VertexId id_bound = t.vertex_id_bound();
  const std::vector<pdt::VertexId> live_before = t.vertices();

  t.shrink_to_fit();

  require_valid(t);
  CHECK(cell_set(t) == cells_before);  // same cells, by the same vertex ids
  CHECK(t.cell_id_bound() == t.number_of_cells());  // the live cells fill the ids below the bound
  CHECK(t.vertex_id_bound() == live_before.back() + 1);  // the free ids above the last live one go
  CHECK(t.vertices() == live_before);
  INFO("memory_bytes " << bytes_before << " before, " << t.memory_bytes() << " after");
  CHECK(t.memory_bytes() * 10 < bytes_before);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    CHECK(t.is_vertex(handles[i]) == bool(keep[i]));
    if (keep[i]) CHECK(t.point(in[i].vertex) == pts[i]);
  }
  // A handle names its cell if the cell stayed, and nothing if it moved.
  std::size_t stayed = 0;
  std::vector<pdt::CellHandle> moved;
  for (const auto& [h, q] : handles_before) {
    if (const auto v = t.cell(h)) {
      CHECK(view_vertices(*v) == q);
      ++stayed;
    } else {
      moved.push_back(h);
    }
  }
  CHECK(stayed > 0);
  CHECK(!moved.empty());
  require_same_as_cgal(t, survivors);

  // The removed points again, one at a time: the ids given back are reused
  // (the storage grows back to about its size before, not beyond), and no
  // handle from before the shrink names another cell, also where its id
  // lives again.
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (!keep[i]) t.insert(pts[i]);
  require_valid(t);
  require_same_as_cgal(t, pts);
  CHECK(t.vertex_id_bound() <= id_bound);
  // A moved cell's id that lives again is a newer incarnation than any it had
  // (the id's tag went back to the OS with its record).
  std::size_t moved_ids_back = 0;
  for (const pdt::CellHandle& h : moved) {
    REQUIRE_FALSE(t.cell(h).has_value());
    if (!t.is_cell(h.id)) continue;
    ++moved_ids_back;
    CHECK(t.cell_handle(h.id).incarnation > h.incarnation);
  }
  CHECK(moved_ids_back * 2 > moved.size());
  std::size_t ids_back = 0;
  for (const auto& [h, q] : handles_before) {
    ids_back += t.is_cell(h.id);
    if (const auto v = t.cell(h)) CHECK(view_vertices(*v) == q);
  }
  CHECK(ids_back * 2 > handles_before.size());  // most ids live again
  for (std::size_t i = 0; i < pts.size(); ++i) CHECK(t.is_vertex(handles[i]) == bool(keep[i]));

  // Twice in a row: the second finds nothing more to give.
  t.shrink_to_fit();
  const std::size_t once = t.memory_bytes();
  t.shrink_to_fit();
  CHECK(t.memory_bytes() == once);
  require_same_as_cgal(t, pts);
}

TEST_CASE("shrink_to_fit when empty, below dimension 3 and after a clear", "[shrink]") {
  pdt::Triangulation t;
  t.shrink_to_fit();
  CHECK(t.dimension() == -1);
  CHECK(t.memory_bytes() == pdt::Triangulation().memory_bytes());  // the infinite vertex
  // Collinear, then coplanar: no cells; the vertex ids stay.
  std::vector<Point3> line, plane;
  for (int i = 0; i < 600; ++i) line.push_back({i * 0.5, 0, 0});
  std::vector<pdt::VertexId> ids = insert_all(t, line);
  for (std::size_t i = 0; i < ids.size(); ++i)
    if (i % 7) t.remove(ids[i]);
  t.shrink_to_fit();
  require_valid(t);
  CHECK(t.dimension() == 1);
  std::vector<Point3> expected;
  for (std::size_t i = 0; i < ids.size(); i += 7) {
    CHECK(t.is_vertex(ids[i]));
    expected.push_back(line[i]);
  }
  for (int i = 0; i < 300; ++i) plane.push_back({i % 20 * 1.0, i / 20 * 1.0 + 0.25, 0});
  for (const Point3& p : plane) (void)t.insert(p);
  expected.insert(expected.end(), plane.begin(), plane.end());
  require_same_as_cgal(t, expected);
  t.shrink_to_fit();
  CHECK(t.dimension() == 2);
  // Then 3D, shrunk, and back to 2D by removing the one point off the plane.
  const pdt::VertexId apex = t.insert({3, 3, 2}).vertex;
  t.shrink_to_fit();
  expected.push_back({3, 3, 2});
  require_same_as_cgal(t, expected);
  t.remove(apex);
  expected.pop_back();
  t.shrink_to_fit();
  require_same_as_cgal(t, expected);
  t.clear();
  t.shrink_to_fit();
  CHECK(t.memory_bytes() == pdt::Triangulation().memory_bytes());  // the infinite vertex
  const std::vector<Point3> pts = random_points(2000, 73);
  insert_all(t, pts);
  require_same_as_cgal(t, pts);
}

TEST_CASE("shrink_to_fit is refused while an engine is attached and from a change hook", "[shrink][engine]") {
  pdt::Triangulation t;
  const std::vector<Point3> pts = random_points(500, 74);
  insert_all(t, pts);
  const std::set<Quad> cells = cell_set(t);
  {
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, kUnit, options_with(2));
      try {
        t.shrink_to_fit();
        FAIL("shrink_to_fit was not refused");
      } catch (const pdt::Error& err) {
        CHECK(err.code() == pdt::ErrorCode::invalid_argument);
        CHECK(std::string(err.what()).find("shrink_to_fit while an Engine is attached") != std::string::npos);
      }
    });
  }
  std::string refused;
  t.set_change_hook([&](const pdt::Changes&) {
    try {
      t.shrink_to_fit();
    } catch (const pdt::Error& err) {
      refused = err.what();
    }
  });
  (void)t.insert({0.5, 0.5, 0.123});
  CHECK(refused.find("shrink_to_fit from the triangulation's own change hook") != std::string::npos);
  t.set_change_hook({});
  CHECK(cell_set(t).size() > cells.size());
  require_valid(t);
}

TEST_CASE("an engine after shrink_to_fit reuses what was given back and equals CGAL", "[shrink][engine]") {
  const std::vector<Point3> pts = random_points(scaled(40000, 8000), 75);
  pdt::Triangulation t;
  const std::vector<pdt::InsertResult> in = t.insert_batch(pts);
  std::vector<Point3> expected;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (i % 50 == 0)
      expected.push_back(pts[i]);
    else
      t.remove(in[i].vertex);
  }
  const pdt::VertexId id_bound = t.vertex_id_bound();
  t.shrink_to_fit();
  const std::vector<Point3> more = random_points(scaled(30000, 6000), 76);
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, kUnit, options_with(2));
    std::atomic<int> errors{0};
    std::vector<pdt::Engine::Ticket> tickets;
    for (const Point3& p : more) tickets.push_back(e.insert(p, [&](const pdt::OpResult& r) {
      if (r.error) errors.fetch_add(1);
    }));
    e.drain();
    // Undo every third, through the engine.
    std::vector<pdt::Engine::Ticket> undo;
    for (std::size_t i = 0; i < tickets.size(); i += 3) undo.push_back(tickets[i]);
    e.remove_insertions(undo);
    e.drain();
    CHECK(errors.load() == 0);
  });
  for (std::size_t i = 0; i < more.size(); ++i)
    if (i % 3) expected.push_back(more[i]);
  require_valid(t);
  require_same_as_cgal(t, expected);
  // The engine's vertices went into the ids given back before any new one.
  CHECK(t.vertex_id_bound() <= id_bound + 4096);
}

TEST_CASE("for_each_kept gives the ranges a skip list leaves", "[shrink]") {
  using pdt::detail::IdRange;
  auto kept = [](std::size_t begin, std::size_t end, std::vector<IdRange> skip) {
    std::vector<std::pair<std::size_t, std::size_t>> out;
    pdt::detail::for_each_kept(begin, end, skip, [&](std::size_t b, std::size_t e) { out.emplace_back(b, e); });
    return out;
  };
  using R = std::vector<std::pair<std::size_t, std::size_t>>;
  CHECK(kept(1, 10, {}) == R{{1, 10}});
  CHECK(kept(1, 10, {{3, 5}, {7, 8}}) == R{{1, 3}, {5, 7}, {8, 10}});
  CHECK(kept(1, 10, {{1, 4}, {8, 12}}) == R{{4, 8}});
  CHECK(kept(4, 6, {{1, 5}, {5, 6}}) == R{});
  CHECK(kept(5, 9, {{1, 3}, {10, 12}}) == R{{5, 9}});
  CHECK(kept(2, 9, {{1, 3}, {4, 5}, {6, 20}}) == R{{3, 4}, {5, 6}});
  CHECK(kept(3, 3, {{1, 2}}) == R{});
}

TEST_CASE("after shrink_to_fit the id bound follows the last live vertex and scans skip the ids given back",
          "[shrink]") {
  const std::vector<Point3> pts = random_points(scaled(30000, 8000), 77);
  pdt::Triangulation t;
  const std::vector<pdt::InsertResult> in = t.insert_batch(pts);
  std::vector<pdt::VertexHandle> handles;
  for (const auto& r : in) handles.push_back(r.handle());
  // The later two thirds by id go (the bound drops past the last live
  // vertex), and of the rest all but every 600th (runs given back below it).
  pdt::VertexId top = 0;
  for (const auto& r : in) top = std::max(top, r.vertex);
  const pdt::VertexId cut = top / 3;
  std::vector<Point3> expected;
  pdt::VertexId last_live = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const pdt::VertexId v = in[i].vertex;
    if (v < cut && v % 600 == 0) {
      expected.push_back(pts[i]);
      last_live = std::max(last_live, v);
    } else {
      t.remove(v);
    }
  }
  t.shrink_to_fit();
  CHECK(t.vertex_id_bound() == last_live + 1);
  require_valid(t);
  require_same_as_cgal(t, expected);

  // Scans do not read the records given back: one is made to look live,
  // and no scan finds it (validate, vertices(), the jump grid's rebuilds
  // as the mesh grows again).
  auto& m = pdt::detail::impl_of(t);
  const std::vector<pdt::detail::IdRange> released = m.released_ranges();
  REQUIRE(!released.empty());
  const pdt::VertexId decoy = released.front().first + 1;
  m.verts[decoy].multiplicity = 1;
  m.verts[decoy].p = pdt::detail::KPoint(0.5, 0.5, 0.5);
  const std::vector<pdt::VertexId> ids = t.vertices();
  CHECK(std::find(ids.begin(), ids.end(), decoy) == ids.end());
  CHECK(ids.size() == expected.size());
  require_valid(t);
  const pdt::detail::JumpGrid grid = pdt::detail::JumpGrid::build(m.verts, 0, released);
  CHECK(grid.built_for == expected.size());
  m.verts[decoy].multiplicity = 0;  // all-zero again, as released records are
  m.verts[decoy].p = pdt::detail::KPoint(0, 0, 0);

  // Growing again: ids come from the released runs first, then past the
  // bound; handles to the ids above the old bound stay dead when those ids
  // are handed out again.
  const std::vector<Point3> more = random_points(scaled(40000, 10000), 78);
  for (const Point3& p : more) (void)t.insert(p);
  expected.insert(expected.end(), more.begin(), more.end());
  require_valid(t);
  require_same_as_cgal(t, expected);
  for (std::size_t i = 0; i < in.size(); ++i)
    if (in[i].vertex >= cut || in[i].vertex % 600 != 0) CHECK_FALSE(t.is_vertex(handles[i]));
  CHECK(m.released_ranges().empty());
  CHECK(t.vertices().size() == expected.size());
}
