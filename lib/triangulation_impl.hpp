#pragma once
// The data structure behind pdt::Triangulation, and the kernel's operations.
// The rooms, in the order an operation flows through them:
//   storage.hpp, stable_array.hpp  the records and the arrays that never move
//   pools.cpp        per-thread pools of cell and vertex ids, count folding
//   vertex_locks.cpp the per-vertex try-locks
//   locate.cpp       jump-and-walk location (jump_grid.hpp), the conflict test
//   insertion.cpp    Bowyer-Watson: the conflict zone and the cone that refills it
//   removal.cpp      the hole, its link triangulation, sewing it in
//   flat_state.cpp   dimension < 3, the first tetrahedron, dropping back
//   validate.cpp     every invariant below, checked
//
// Storage (see storage.hpp for the record encodings):
//   cells[c], verts[v] index-based, in StableArrays, so ids never move.
//   marks[c]  visit stamp of the last conflict-zone search that touched c. A
//             stamp is (context id << 48 | counter), so searches of different
//             threads, or earlier ones of the same thread, never match.
//             Only a thread holding a facet of c exclusively writes marks[c]
//             (two such threads would share a vertex), so a search owns the
//             marks it reads.
//
// Invariants while dimension() == 3 (checked by validate()):
//   I1 a live cell has 4 distinct live vertices; a free cell has v[0] == no_vertex
//      and n[0] is the next free cell of the pool that owns it.
//   I2 adjacency is symmetric: cells[c].n[i] == 4d+j  <=>  cells[d].n[j] == 4c+i,
//      and the two cells agree on the 3 vertices of the shared facet, seen in
//      opposite orientations.
//   I3 every finite cell is positively oriented (CGAL::orientation > 0); an
//      infinite cell is oriented so that putting, in place of the infinite
//      vertex, a point beyond its hull facet makes it positive.
//   I4 a live finite vertex's cell contains it; multiplicity >= 1. A free vertex
//      has multiplicity 0 and cell == the next free vertex of its pool.
//   I5 every facet is locally Delaunay under the symbolic perturbation, and the
//      hull is convex (the infinite cells pass the same test).
//   I6 V - E + F - C = 0 counting the infinite vertex (a triangulated 3-sphere).
// While dimension() < 3 there is no cell: the live vertices are listed in
// `flat`, verts[v].cell holds v's position in `flat`, and `basis` holds
// dimension()+1 affinely independent vertices.
//
// Concurrency (the engine; paper §3.2). Each vertex has one lock word: 0 free,
// k > 0 held shared by k readers, -(owner) held exclusively by context `owner`.
// A thread reads a cell only while it holds locks on the cell's 4 finite
// vertices (the infinite vertex is never locked: every cell has at least 3
// finite vertices, so holding those is enough to exclude writers), and writes
// a cell, or a vertex's fields, only while holding them exclusively. All
// locks are try-locks: an operation that meets a held lock releases what it
// holds and reports a rollback *before* it has changed anything. A cell that
// shares a facet with a cell we hold is stable too (its writer would need our
// facet's vertices), which lets a walk or a conflict-zone search read one step
// ahead. verts[0].cell is never read or written (it would be a point of
// contention).
//
// The kernel <-> engine contract. The kernel's operations take the context
// to run in and return what they did (OpStatus plus their result); the engine
// never reads results out of a context. Operations that change the dimension
// report needs_global, and the engine reruns them with the world stopped in
// the sequential context. While an engine drives the triangulation,
// grid_growth says so and the engine, not the kernel, regrows the jump grid.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "affine_basis.hpp"
#include "jump_grid.hpp"
#include "op_context.hpp"
#include "pdt/triangulation.hpp"
#include "predicates.hpp"
#include "stable_array.hpp"
#include "storage.hpp"

namespace pdt {

struct Triangulation::Impl {
  using CellRec = detail::CellRec;
  using VertexRec = detail::VertexRec;
  using KPoint = detail::KPoint;
  using OpStatus = detail::OpStatus;
  using OpContext = detail::OpContext;

  explicit Impl(bool is_small = false);
  ~Impl();

  // -- storage ---------------------------------------------------------------
  detail::StableArray<CellRec> cells;
  detail::StableArray<std::uint64_t> marks;
  detail::StableArray<VertexRec> verts;

  std::atomic<int> dim{-1};
  // Totals; exact whenever no operation is running and every engine worker
  // has folded its deltas (it does before going idle or to sleep).
  std::atomic<std::int64_t> n_vertices{0}, n_cells{0}, n_finite_cells{0};

  // dimension < 3
  std::vector<VertexId> flat;
  std::unordered_map<std::uint64_t, std::vector<VertexId>> flat_index;  // hash(point) -> vertices
  detail::AffineBasis basis;

  const bool is_small;  // a removal's scratch triangulation: no jump grid
  detail::JumpGrid grid;
  // Who regrows the jump grid as the vertex count grows.
  enum class GridGrowth { kernel, engine } grid_growth = GridGrowth::kernel;
  std::unique_ptr<OpContext> seq;  // the context of single-threaded calls
  std::atomic<VertexId> recent_vertex{no_vertex};  // some recently inserted vertex (a walk start)

  // -- primitives ------------------------------------------------------------
  bool cell_alive(CellId c) const { return c < cells.size() && cells[c].v[0] != no_vertex; }
  bool cell_infinite(CellId c) const {
    const VertexId* v = cells[c].v;
    return v[0] == 0 || v[1] == 0 || v[2] == 0 || v[3] == 0;
  }
  bool vertex_alive(VertexId v) const { return v != 0 && v < verts.size() && verts[v].multiplicity > 0; }
  const KPoint& pt(VertexId v) const { return verts[v].p; }
  int index_of(CellId c, VertexId v) const {
    const VertexId* cv = cells[c].v;
    return cv[0] == v ? 0 : cv[1] == v ? 1 : cv[2] == v ? 2 : cv[3] == v ? 3 : -1;
  }
  void set_adjacency(CellId c, int i, CellId d, int j) {
    cells[c].n[i] = 4 * d + static_cast<std::uint32_t>(j);
    cells[d].n[j] = 4 * c + static_cast<std::uint32_t>(i);
  }
  void set_vertex_cell(VertexId w, CellId c) {
    if (w != 0) verts[w].cell = c;
  }

  // -- pools (pools.cpp) --------------------------------------------------------
  CellId alloc_cell(OpContext& ctx);
  void free_cell(OpContext& ctx, CellId c);
  VertexId alloc_vertex(OpContext& ctx, const KPoint& p);
  void free_vertex(OpContext& ctx, VertexId v);
  // Gives a context's pooled ids back to another context (engine shutdown).
  void merge_pools(OpContext& into, OpContext& from);
  void fold_counters(OpContext& ctx);
  void end_op_counters(OpContext& ctx);  // folds now, or later for an engine worker
  void clear();

  // -- locks (vertex_locks.cpp; no-ops when !ctx.locking) -----------------------
  bool lock_shared(OpContext& ctx, VertexId v);
  bool lock_exclusive(OpContext& ctx, VertexId v);  // upgrades a shared lock we hold
  bool lock_cell_exclusive(OpContext& ctx, CellId c);
  void release_all(OpContext& ctx);

  // -- location (locate.cpp) ----------------------------------------------------
  // The cell where a visibility walk from `start` ends: a finite cell whose
  // closure contains p, or an infinite cell whose hull facet p is strictly
  // beyond (then *outside = true). Locks shared as it goes; no_cell means a
  // rollback.
  CellId walk(OpContext& ctx, const KPoint& p, CellId start, bool* outside) const;
  VertexId start_vertex(OpContext& ctx, const KPoint& p, VertexId hint) const;
  CellId finite_cell_of(VertexId v) const;
  // Is c in conflict with p: p inside c's perturbed circumsphere (an infinite
  // cell: beyond its hull facet, or on its plane inside its circumcircle)?
  bool in_conflict(CellId c, const KPoint& p) const;
  void grid_note(OpContext& ctx, VertexId v);  // v was just inserted
  void grid_rebuild(std::size_t slots = 0);

  // -- insertion (insertion.cpp) --------------------------------------------------
  struct Inserted {
    InsertResult result;
    std::uint64_t stamp = 0;  // the incarnation of result.vertex
  };
  OpStatus insert(OpContext& ctx, const KPoint& p, VertexId hint, Inserted& out);
  OpStatus gather_conflict_zone(OpContext& ctx, const KPoint& p, CellId c0);
  void cone_from_vertex(OpContext& ctx, VertexId v);

  // -- removal (removal.cpp) ------------------------------------------------------
  // expected_stamp: 0 = any; else the vertex must be that incarnation.
  OpStatus remove(OpContext& ctx, VertexId v, std::uint64_t expected_stamp, RemoveResult& out);
  OpStatus remove_3d(OpContext& ctx, VertexId v);
  // The cells incident to v (v held), in ctx.star_seen's order of discovery.
  void collect_star(OpContext& ctx, VertexId v, std::vector<CellId>& out);
  void fill_hole_flat_link(OpContext& ctx, VertexId v);
  void sew_link_triangulation(OpContext& ctx, VertexId v);

  // -- dimension < 3 (flat_state.cpp; single-threaded only) ----------------------
  InsertResult insert_flat(OpContext& ctx, const KPoint& p);
  void remove_flat(OpContext& ctx, VertexId v);
  void recompute_basis();
  void build_3d(OpContext& ctx, VertexId apex);
  void drop_to_flat(OpContext& ctx);
  static std::uint64_t point_hash(const KPoint& p);
  VertexId find_flat(const KPoint& p) const;

  bool validate(std::string* why) const;  // validate.cpp
};

namespace detail {

// The library's access to a Triangulation's implementation (the engine, the
// I/O, pdt's own tests); not part of the public API.
struct ImplAccess {
  static Triangulation::Impl& of(Triangulation& t) { return *t.impl_; }
  static const Triangulation::Impl& of(const Triangulation& t) { return *t.impl_; }
};
inline Triangulation::Impl& impl_of(Triangulation& t) { return ImplAccess::of(t); }
inline const Triangulation::Impl& impl_of(const Triangulation& t) { return ImplAccess::of(t); }

}  // namespace detail

}  // namespace pdt
