// SPDX-License-Identifier: MIT
#pragma once
// pdt::Triangulation: a dynamic 3D Delaunay triangulation with exact, robust
// insertion and removal.
//
// What it computes. After any sequence of insert() and remove() calls the
// triangulation is *the* Delaunay triangulation of the points currently in it,
// ties among cospherical points being broken by the symbolic perturbation of
// Devillers & Teillaud (points ordered lexicographically by (x, y, z)), the
// rule CGAL's Delaunay_triangulation_3 uses. That triangulation is unique for
// any point set that is not entirely coplanar, so the result depends neither on
// the order of operations nor on the thread count, and equals CGAL's
// tetrahedron for tetrahedron. The convex hull is exact: the unbounded outside
// is covered by "infinite" cells sharing the infinite vertex (id 0), never by a
// bounding box.
//
// Lower dimensions. While all points are coplanar (fewer than 4 points, or a
// start with many coplanar or collinear points) there is no tetrahedron: the
// vertices are kept and dimension() tells how many dimensions they span; the
// first point off their plane builds the 3D triangulation. Removals that make
// the set coplanar again drop back to that state.
//
// Duplicates. Inserting a point equal to an existing vertex returns that vertex
// and raises its multiplicity; remove() lowers it, and the vertex disappears
// when the multiplicity reaches 0. So the triangulation is always that of the
// distinct points whose insertions have not all been undone.
//
// Ids. A VertexId stays valid until its vertex disappears; the id may then be
// reused by a later insertion. Storage grows without moving ids. Handles
// (changes.hpp) add the incarnation, so a stale one is recognised.
//
// Threads. Every const method may be called from many threads at once, as
// long as nothing mutates the triangulation meanwhile: no insert/remove/clear
// in progress and no engine operation in flight (after Engine::drain(), an
// attached engine's triangulation is quiescent until the next submission).
// While an engine works, read through it (Engine::locate, nearest_vertex,
// visit). Mutating methods are for one thread at a time, and are refused with
// pdt::Error(invalid_argument) while an Engine is attached: the engine owns
// the triangulation from its construction to its destruction.
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "pdt/changes.hpp"
#include "pdt/geometry.hpp"

namespace pdt {

namespace detail {
struct ImplAccess;
}

struct InsertResult {
  VertexId vertex = no_vertex;  // the new vertex, or the existing one equal to the point
  bool inserted = false;        // false: the point was a duplicate, multiplicity raised
  std::uint64_t incarnation = 0;  // the vertex's incarnation (see changes.hpp)
  VertexHandle handle() const { return {vertex, incarnation}; }
};

enum class RemoveResult {
  removed,              // the vertex is gone
  multiplicity_lowered  // the point had been inserted more than once; the vertex stays
};

// Where a point lies relative to the triangulation.
// While dimension() < 3 there are no cells: locate gives on_vertex (with
// cell == no_cell) for a point at a vertex, and none for any other point.
enum class LocateKind { none /*dimension < 3, not at a vertex*/, in_cell, on_facet, on_edge, on_vertex, outside_hull };

struct LocateResult {
  LocateKind kind = LocateKind::none;
  CellId cell = no_cell;        // a cell containing the point (an infinite cell if outside); no_cell in dimension < 3
  VertexId vertex = no_vertex;  // for on_vertex: the vertex at the point
};

// A hint for location: a vertex or cell near the point, as a refiner usually knows.
struct Hint {
  VertexId vertex = no_vertex;
  CellId cell = no_cell;
};

struct TriangulationStats {
  std::uint64_t insertions = 0;        // successful insert() calls, duplicates included
  std::uint64_t duplicates = 0;        // insert() calls that found an existing vertex
  std::uint64_t removals = 0;          // remove() calls
  std::uint64_t cells_created_by_insert = 0;
  std::uint64_t cells_created_by_remove = 0;  // cells sewn into holes
  std::uint64_t cells_touched_by_remove = 0;  // hole cells + small-triangulation cells built
  std::uint64_t walk_steps = 0;        // visibility-walk steps over all locations
  TriangulationStats& operator+=(const TriangulationStats& o) {
    insertions += o.insertions;
    duplicates += o.duplicates;
    removals += o.removals;
    cells_created_by_insert += o.cells_created_by_insert;
    cells_created_by_remove += o.cells_created_by_remove;
    cells_touched_by_remove += o.cells_touched_by_remove;
    walk_steps += o.walk_steps;
    return *this;
  }
};

class Triangulation {
 public:
  // Throws pdt::Error (invalid_argument) if PDT_HUGE_PAGES is set to anything
  // but 0 or 1 (README, Design, Huge pages; empty counts as unset), std::bad_alloc
  // if the address space for its arrays cannot be reserved. The variable is
  // read once per process, by the first construction that reads a valid
  // value: changing it later changes nothing.
  Triangulation();
  // Destroying a triangulation while an engine is attached to it breaks the
  // rule that it outlives its engine: the process stops (std::abort) with a
  // message naming the rule, instead of corrupting memory later. So does
  // destroying it from its own change hook (the change is still being made).
  ~Triangulation();
  // Moving is refused (pdt::Error) while an engine is attached to either side.
  Triangulation(Triangulation&&);
  Triangulation& operator=(Triangulation&&);
  Triangulation(const Triangulation&) = delete;
  Triangulation& operator=(const Triangulation&) = delete;

  // -- mutation (one thread; refused while an engine is attached) -------------
  // Inserts p. Throws pdt::Error(non_finite_coordinate) for NaN/Inf and changes nothing.
  InsertResult insert(const Point3& p, Hint hint = {});
  // Inserts p only if cell h is still alive; otherwise inserts nothing and
  // returns {no_vertex, false}.
  InsertResult insert_if_alive(const Point3& p, CellHandle h);
  // Inserts a batch in an order of its own (a biased randomized insertion
  // order along a Hilbert curve, the order of CGAL's range insertion; the same
  // on every run): consecutive points are close, so it is about twice
  // as fast as inserting the same points one by one in a random order. The
  // result is the same, the triangulation being unique. Results come in the
  // batch's order. Checks every point first: throws pdt::Error
  // (non_finite_coordinate) naming the first bad one and inserts nothing.
  // Copies of one point: one of them reports inserted = true (which one
  // follows the insertion order, not the batch's), the others false, all with
  // the same vertex. A change hook (set_change_hook) that throws stops the
  // batch there: the exception propagates, the points inserted before it
  // (and the one whose hook threw) stay, the rest are not inserted, and the
  // results are lost; is_vertex / locate tell which points are in.
  std::vector<InsertResult> insert_batch(std::span<const Point3> points);
  // Undoes one insertion of v. Throws pdt::Error(unknown_vertex) for the infinite
  // vertex, an id never issued or a vertex already gone, and changes nothing.
  RemoveResult remove(VertexId v);
  // The same for one incarnation: a handle whose vertex is gone (even if its
  // id was reused since) is refused with unknown_vertex.
  RemoveResult remove(VertexHandle v);
  // Empties the triangulation: every cell and vertex dies without a change
  // report; handles from before read as dead; the id bounds start again.
  void clear();
  // Gives back to the system the storage of freed cells and vertices. Freed
  // ids are reused by later insertions, so storage keeps the size of the
  // largest mesh held so far: 1M vertices removed down to the last 10k
  // inserted keep about 290 MB until this call, then about 3 MB. Vertex ids
  // never move, so a page of vertex records that still holds a live one
  // stays: the same 1M down to 10k chosen at random keep about 38 MB. The
  // free ids above the highest live one go altogether (vertex_id_bound()
  // drops); those below it that were given back are skipped by later scans
  // (vertices(), validate(), the writers, the jump grid's rebuilds), whose
  // time then follows the mesh held. This call's own time and memory traffic
  // are in proportion to the largest size. The triangulation is the same; every
  // VertexId and VertexHandle stays valid; live cells may move to lower ids,
  // and a CellHandle to a moved cell reads as dead afterwards (one to a cell
  // that stayed still names it). Not a change: the change hook is not called.
  // Throws only to refuse a call while an engine is attached or from the
  // change hook (pdt::Error, invalid_argument).
  void shrink_to_fit();
  // Calls hook inside every later insert/remove that creates or deletes a
  // vertex (see changes.hpp), with the cells it created, and with those it
  // destroyed when report_destroyed. An empty hook turns reporting off.
  // While an Engine is attached, the engine's operations report to the
  // engine's hook (Engine::set_change_hook), not to this one; this one
  // reports again once the engine is gone.
  void set_change_hook(ChangeHook hook, bool report_destroyed = false);

  // -- queries (const: thread-safe on a quiescent triangulation) ---------------
  int dimension() const;                         // -1 empty, 0..3
  std::size_t number_of_vertices() const;        // distinct finite vertices
  std::size_t number_of_finite_cells() const;    // tetrahedra (0 while dimension < 3)
  std::size_t number_of_cells() const;           // finite + infinite
  bool is_vertex(VertexId v) const;              // a live finite vertex
  bool is_vertex(VertexHandle v) const;          // that incarnation is live
  VertexHandle vertex_handle(VertexId v) const;  // a dead handle (incarnation 0) unless is_vertex(v)
  Point3 point(VertexId v) const;                // pdt::Error (unknown_vertex) unless is_vertex(v)
  std::uint32_t multiplicity(VertexId v) const;  // 0 if not a vertex
  LocateResult locate(const Point3& p, Hint hint = {}) const;
  // The vertex nearest to p; no_vertex if empty. In dimension 3 a walk and a
  // search of the neighbourhood; below it (coplanar or collinear points)
  // every vertex is compared, in time proportional to their number (and an
  // engine runs it with its other workers stopped).
  VertexId nearest_vertex(const Point3& p) const;
  // Finite tetrahedra as vertex ids, positively oriented.
  std::vector<std::array<VertexId, 4>> finite_cells() const;
  // Live finite vertex ids, increasing.
  std::vector<VertexId> vertices() const;
  // Raw access for iteration without copies: ids below cell_id_bound() may be
  // live or free; is_cell() tells. A cell's facet i is opposite vertex i;
  // neighbor(c, i) shares that facet. cell_vertex and cell_neighbor refuse
  // (pdt::Error, invalid_argument) a c not below cell_id_bound() or an i
  // outside 0..3; what they return for a free cell means nothing.
  CellId cell_id_bound() const;
  bool is_cell(CellId c) const;
  bool is_finite_cell(CellId c) const;
  VertexId cell_vertex(CellId c, int i) const;
  CellId cell_neighbor(CellId c, int i) const;
  // Every live vertex id is below it (shrink_to_fit may lower it).
  VertexId vertex_id_bound() const;
  CellHandle cell_handle(CellId c) const;          // pdt::Error (invalid_argument) unless is_cell(c)
  // The cell of h if that incarnation is still live; nothing if it died.
  std::optional<CellView> cell(CellHandle h) const;

  // Checks every invariant of the structure (see lib/triangulation_impl.hpp)
  // and the local Delaunay property of every facet with exact predicates.
  // Returns true when all hold; otherwise false and, if why is given, what failed.
  bool validate(std::string* why = nullptr) const;

  // What this triangulation's own operations did. An attached engine's
  // workers count theirs apart and add them here when the engine is
  // destroyed; until then they are not in it (Engine::stats() counts the
  // engine's operations meanwhile).
  const TriangulationStats& stats() const;
  std::size_t memory_bytes() const;  // bytes held by cell and vertex storage and the jump grid

  struct Impl;  // lib/triangulation_impl.hpp

 private:
  friend struct detail::ImplAccess;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pdt
