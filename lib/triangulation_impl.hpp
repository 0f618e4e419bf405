// SPDX-License-Identifier: MIT
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
//   shrink.cpp       shrink_to_fit: live cells moved down, freed storage given back
//
// Storage (see storage.hpp for the record encodings):
//   cells[c], verts[v] index-based, in StableArrays, so ids never move.
//   tags[c]   incarnation << 2 | mark. The incarnation counts the allocations
//             of id c over the triangulation's whole life (clear() and
//             shrink_to_fit() give tags back but keep tag_floor above them),
//             so (c, incarnation) names one cell ever: an id whose cell dies
//             at retire_at (2^30 - 2) or later is retired (never reused: one
//             id per 2^30 allocations of it), so the 30-bit count never
//             wraps (retire_at). The mark (1 in, 2 out)
//             is set by a conflict-zone search on the cells it meets and
//             cleared before the search returns (a zone found whole keeps
//             its marks until the cone that replaces it renews or frees its
//             cells, in the same operation), so outside an operation every
//             live cell's mark is 0 (I7). A dead id's mark is 3 (free_cell,
//             clear()) until renew() makes it live again, or its tag is 0
//             (never allocated): so a tag holding a handle's incarnation with
//             a mark other than 3 names that handle's cell, alive (I8;
//             hold_cell). Only a thread holding a facet of c exclusively
//             writes c's mark (two such threads would share a vertex), so a
//             search owns the marks it reads; the word is atomic (relaxed)
//             because a reader holding another vertex of c may read the
//             incarnation meanwhile.
//   Vertex incarnations (VertexRec.stamp) come in blocks from a source
//   shared by every triangulation of the process, and context ids (lock
//   owners) from a life-long counter, so neither repeats however many
//   engines come and go (nor, for stamps, across triangulations).
//
// Invariants while dimension() == 3 (checked by validate()):
//   I1 a live cell has 4 distinct live vertices; a free cell has v[0] == no_vertex
//      (once freed, every slot) and n[0] is the next free cell of the pool that owns it.
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
//   I7 no live cell is marked.
//   I8 an id below cells.size() that is not live has tag 0 or mark_free (not
//      kept by a removal's small triangulation: nothing holds handles to it).
// Always (checked by validate()): every live vertex lies in filter's box, and
// the filter's epsilons are those of its box (box_filter.hpp).
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
// grid_growth says so and the engine, not the kernel, regrows the jump grid;
// `engine` names it, and the public mutators refuse to run.
//
// Exception safety. An operation obtains everything it needs (pool cells, map
// room, report room, the vertex) before its first change, so an allocation
// failure leaves the triangulation as it was; a global step (build_3d,
// drop_to_flat) reserves first or restores the state it started from.
#include <array>
#include <atomic>
#include <cassert>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "affine_basis.hpp"
#include "box_filter.hpp"
#include "flat_index.hpp"
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

  // This storage's number (CellHandle::mesh): from a process-wide counter,
  // never 0; moves with the storage, kept by clear().
  const std::uint32_t mesh_id;

  // -- storage ---------------------------------------------------------------
  detail::StableArray<CellRec> cells;
  detail::StableArray<std::atomic<std::uint32_t>> tags;
  detail::StableArray<VertexRec> verts;
  static constexpr std::uint32_t mark_in = 1, mark_out = 2, mark_free = 3, mark_bits = 3;
  static constexpr std::uint32_t last_incarnation = ~std::uint32_t{0} >> 2;

  std::atomic<int> dim{-1};
  // Totals; exact whenever no operation is running and every engine worker
  // has folded its deltas (it does before going idle or to sleep).
  std::atomic<std::int64_t> n_vertices{0}, n_cells{0}, n_finite_cells{0};

  // dimension < 3
  std::vector<VertexId> flat;
  detail::FlatIndex flat_index;  // the flat vertices by point
  detail::AffineBasis basis;

  const bool is_small;  // a removal's scratch triangulation: no jump grid
  // A box holding every point ever inserted since clear() (and an attached
  // engine's domain): the predicates among its points skip CGAL's per-call
  // bound (box_filter.hpp). Grown only by single-threaded insertions while no
  // engine is attached, and by an engine attaching (before its workers run);
  // engine workers only read it.
  detail::BoxFilter filter;
  detail::JumpGrid grid;
  detail::WalkWatch walk_watch;  // the kernel's (grid_note); an engine's workers have their own
  // Who regrows the jump grid as the vertex count grows.
  enum class GridGrowth { kernel, engine } grid_growth = GridGrowth::kernel;
  std::unique_ptr<OpContext> seq;  // the context of single-threaded calls
  // Free ids beyond what each context keeps (pools.cpp): a context that frees
  // more than it allocates gives segments here, one short of ids takes them
  // before carving new storage, so the storage follows the live mesh however
  // the work moves between the engine's workers.
  mutable std::mutex spare_mutex;  // mutable: const scans read released_vertices under it
  // Some cell id has reached retire_at (then reserve_cells looks for
  // such ids in the ranges it carves; clear() and shrink_to_fit() keep
  // incarnations counting, above tag_floor for the tags they give back).
  std::atomic<bool> some_id_retiring{false};
  detail::SpareSegments spare_cells, spare_vertices;
  // Vertex ids whose records shrink_to_fit() gave back to the OS (all-zero,
  // on no free list): taken as fresh ranges, vertex_chunk ids at a time,
  // before the array grows. Under spare_mutex; released_vertex_count is its
  // total, read without the mutex to skip it when there is none.
  // Invariant (validate checks all but the records, which it does not read):
  // the runs are non-empty, disjoint, inside [1, verts.size()), their ids
  // free (multiplicity 0, records all-zero, on no free list); the counts sum
  // to released_vertex_count.
  struct IdRun {
    std::uint32_t first, count;
  };
  std::vector<IdRun> released_vertices;
  std::atomic<std::size_t> released_vertex_count{0};
  // released_vertices as a skip list for scans over the vertex ids
  // (id_ranges.hpp: sorted, disjoint); empty when there is none. Scans
  // read each live vertex's record through it, never a released one's.
  std::vector<detail::IdRange> released_ranges() const;
  // The vertex ids handed out so far, released ones left out: what the
  // engine sizes its jump grid by (after shrink_to_fit the id bound can be
  // far above the mesh).
  std::size_t vertex_ids_in_use() const {
    return verts.size() - released_vertex_count.load(std::memory_order_relaxed);
  }
  // Cell ids below tag_floor_end whose tags were given back (shrink_to_fit,
  // clear()) held incarnations up to tag_floor: reserve_cells starts such an
  // id there, so that its next cell is a newer incarnation than any handle to
  // the id names. Written only while no engine is attached.
  std::uint32_t tag_floor = 0;
  std::size_t tag_floor_end = 0;
  std::atomic<VertexId> recent_vertex{no_vertex};  // some recently inserted vertex (a walk start)
  ChangeHook hook;                 // Triangulation::set_change_hook's, for seq
  bool report_destroyed = false;
  std::atomic<const void*> engine{nullptr};  // the attached engine, if any

  // Life-long sources (clear() keeps them).
  std::atomic<std::uint32_t> next_context_id{2};  // 1 is seq
  std::uint32_t new_context_id();
  std::uint64_t new_incarnation(OpContext& ctx);  // from a source shared by the process (pools.cpp)

  // -- primitives ------------------------------------------------------------
  bool cell_alive(CellId c) const { return c < cells.size() && cells[c].v[0] != no_vertex; }
  bool cell_infinite(CellId c) const {
    const VertexId* v = cells[c].v;
    return v[0] == 0 || v[1] == 0 || v[2] == 0 || v[3] == 0;
  }
  bool vertex_alive(VertexId v) const { return v != 0 && v < verts.size() && verts[v].multiplicity > 0; }
  const KPoint& pt(VertexId v) const { return verts[v].p; }
  std::uint32_t mark(CellId c) const { return tags[c].load(std::memory_order_relaxed) & mark_bits; }
  void set_mark(CellId c, std::uint32_t m) {
    const std::uint32_t t = tags[c].load(std::memory_order_relaxed);
    tags[c].store((t & ~mark_bits) | m, std::memory_order_relaxed);
  }
  // Whether c's tag names the live cell of handle h (I8): its incarnation,
  // and not freed since. A search may mark that cell out meanwhile.
  bool tag_names(CellId c, std::uint32_t incarnation) const {
    const std::uint32_t t = tags[c].load(std::memory_order_acquire);
    return incarnation != 0 && (t >> 2) == incarnation && (t & mark_bits) != mark_free;
  }
  std::uint32_t incarnation(CellId c) const { return tags[c].load(std::memory_order_relaxed) >> 2; }
  // An id whose cell dies at incarnation retire_at or later is retired (never
  // reused). Renewals go through a free id or a dying zone cell below it, so
  // they make incarnations up to retire_at; the one other renewal, in place
  // (fill_hole_flat_link makes a finite cell infinite, once in its life),
  // adds one more: so the 30-bit count never wraps. The flag spares the
  // tag's load while no id is that old.
  static constexpr std::uint32_t retire_at = last_incarnation - 1;
  bool retires(CellId c) const {
    return some_id_retiring.load(std::memory_order_relaxed) && incarnation(c) >= retire_at;
  }
  // A new incarnation of c, unmarked (c is being (re)made; its writer holds it).
  void renew(CellId c) {
    const std::uint32_t t = tags[c].load(std::memory_order_relaxed);
    assert((t >> 2) < last_incarnation);  // free_cell and reserve_cells retire such ids
    if ((t >> 2) + 1 >= retire_at) [[unlikely]]
      some_id_retiring.store(true, std::memory_order_relaxed);
    tags[c].store(((t >> 2) + 1) << 2, std::memory_order_relaxed);
  }
  // Whether cell c's record names v, read by a thread that may not hold c
  // (hold_cell with an anchor not from a report): a writer holding c's
  // vertices may be writing the record meanwhile. The writers keep plain
  // stores (the cone's 16-byte copy; 4-byte atomic stores there cost the
  // batch 5%), so this read is the one access to a record outside the
  // locks, and ThreadSanitizer is told not to track it. Each slot is one
  // aligned 4-byte load, never torn; what it can see is argued at its use.
  [[gnu::noinline]] __attribute__((no_sanitize("thread"))) bool record_names(CellId c, VertexId v) const {
    const volatile VertexId* slots = cells[c].v;
    for (int i = 0; i < 4; ++i)
      if (slots[i] == v) return true;
    return false;
  }
  CellHandle handle_of(CellId c) const;
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
  // Makes sure the next n alloc_cell calls of ctx cannot fail (they then take
  // no chunk from the shared arrays). Throws std::bad_alloc, changing nothing.
  void reserve_cells(OpContext& ctx, std::size_t n);
  void free_all_cells(OpContext& ctx);  // every live cell (the world is stopped)
  // A range of released vertex ids as ctx's fresh range; false if none.
  bool take_released_vertices(OpContext& ctx);
  // Triangulation::shrink_to_fit (shrink.cpp): single-threaded, no engine.
  void shrink_to_fit();
  VertexId alloc_vertex(OpContext& ctx, const KPoint& p);
  void free_vertex(OpContext& ctx, VertexId v);
  // Gives a context's pooled ids back to another context (engine shutdown).
  void merge_pools(OpContext& into, OpContext& from);
  // A spare segment of cells onto ctx's reserved stack (OpContext::reserved_cells);
  // false if there is none. And the next reserved id (reserved_cells > 0).
  bool reserve_spare_segment(OpContext& ctx);
  CellId pop_reserved_cell(OpContext& ctx);
  // Free-list links (storage.hpp): next id in a list, next spare segment.
  auto cell_next() {
    return [this](std::uint32_t c) -> std::uint32_t& { return cells[c].n[0]; };
  }
  auto cell_link() {
    return [this](std::uint32_t c) -> std::uint32_t& { return cells[c].n[1]; };
  }
  auto vertex_next() {
    return [this](std::uint32_t v) -> std::uint32_t& { return verts[v].cell; };
  }
  auto vertex_link() {
    return [this](std::uint32_t v) -> std::uint32_t& { return verts[v].scratch; };
  }
  template <std::uint32_t S, class Next, class Link>
  void give_id(detail::FreeList& l, std::uint32_t id, detail::SpareSegments& spare, Next next, Link link);
  template <std::uint32_t S, class Next, class Link>
  bool take_spare(detail::FreeList& l, detail::SpareSegments& spare, Next next, Link link);
  void fold_counters(OpContext& ctx);
  void end_op_counters(OpContext& ctx);  // folds now, or later for an engine worker
  void clear();

  // -- change reporting (changes.cpp) ---------------------------------------------
  // Before an operation's first change: starts recording if ctx has a hook and
  // reserves room for the cells it will make and delete (may throw, changing
  // nothing), so that noting them never allocates.
  void begin_report(OpContext& ctx, std::size_t cells_made, std::size_t cells_unmade);
  void note_created(OpContext& ctx, CellId c) {
    if (ctx.recording) ctx.created.push_back(c);
  }
  void note_destroyed(OpContext& ctx, CellId c) {
    if (ctx.recording && ctx.report_destroyed) ctx.destroyed.push_back(handle_of(c));
  }
  // After the changes, while their cells are held: calls the hook.
  void end_report(OpContext& ctx, OpKind kind, VertexId v, std::uint64_t incarnation);
  // The end of a change that completed: the hook (end_report), then the locks
  // released and the counters folded, also when the hook throws (rethrown).
  void finish_change(OpContext& ctx, OpKind kind, VertexId v, std::uint64_t incarnation);

  // -- locks (vertex_locks.cpp; no-ops when !ctx.locking) -----------------------
  // Inline: most contexts take no lock words (the sequential one, an engine's
  // only worker), and the walk and the conflict search ask per vertex.
  bool lock_shared(OpContext& ctx, VertexId v) {  // exclusive when ctx.shares_exclusive
    return !ctx.locking || ctx.alone || v == 0 ||
           (ctx.shares_exclusive ? lock_exclusive_word(ctx, v) : lock_shared_word(ctx, v));
  }
  bool lock_exclusive(OpContext& ctx, VertexId v) {  // upgrades a shared lock we hold
    return !ctx.locking || ctx.alone || v == 0 || lock_exclusive_word(ctx, v);
  }
  bool lock_shared_word(OpContext& ctx, VertexId v);  // the lock words themselves
  bool lock_exclusive_word(OpContext& ctx, VertexId v);
  bool lock_cell_exclusive(OpContext& ctx, CellId c);
  void release_all(OpContext& ctx);
  // Holds v's lock word exclusively, for its lifetime, while a context with
  // outside readers (OpContext::outside_readers) writes v's point,
  // multiplicity or stamp; waits out the readers' brief shared holds. A no-op
  // for every other context: a locking one holds v already, the plain
  // sequential one has no readers.
  class VertexWrite {
   public:
    VertexWrite(Impl& m, const OpContext& ctx, VertexId v) {
      if (ctx.outside_readers && v != 0) take(m.verts[v].lock, ctx);  // else nothing: the usual case
    }
    ~VertexWrite() {
      if (word_) word_->store(0, std::memory_order_release);
    }
    VertexWrite(const VertexWrite&) = delete;
    VertexWrite& operator=(const VertexWrite&) = delete;

   private:
    void take(std::atomic<std::int32_t>& word, const OpContext& ctx);  // vertex_locks.cpp
    std::atomic<std::int32_t>* word_ = nullptr;
  };

  // -- location (locate.cpp) ----------------------------------------------------
  // The cell where a visibility walk from `start` ends: a finite cell whose
  // closure contains p, or an infinite cell whose hull facet p is strictly
  // beyond (then *outside = true). Locks shared as it goes; no_cell means a
  // rollback.
  // eps: filter.eps_for(p) (or none), for the walk's orientation tests.
  CellId walk(OpContext& ctx, const KPoint& p, CellId start, bool* outside, const detail::FilterEps& eps) const;
  VertexId start_vertex(OpContext& ctx, const KPoint& p, VertexId hint) const;
  CellId finite_cell_of(VertexId v) const;
  // Is c in conflict with p: p inside c's perturbed circumsphere (an infinite
  // cell: beyond its hull facet, or on its plane inside its circumcircle)?
  bool in_conflict(CellId c, const KPoint& p, const detail::FilterEps& eps) const;
  // in_conflict's answer when the box filter alone gives it for a finite c
  // (+1 in conflict, -1 not), else 0 (an infinite cell, a determinant
  // within eps, no box): ask in_conflict. No branch on the answer, so a
  // cell's neighbours are tested side by side (gather_conflict_zone).
  int quick_conflict(CellId c, const KPoint& p, const detail::FilterEps& eps) const {
    if (cell_infinite(c)) return 0;
    const CellRec& cr = cells[c];
    return detail::box_side_of_sphere(pt(cr.v[0]), pt(cr.v[1]), pt(cr.v[2]), pt(cr.v[3]), p, eps.insphere);
  }
  void grid_note(OpContext& ctx, VertexId v);  // v was just inserted
  void grid_note_removal(OpContext& ctx);      // a vertex was just removed
  // parallel: an engine's equal slots, built in the current TBB arena (with the world stopped).
  // most: an engine's cap; follow: an engine's tree whatever the crowding.
  void grid_rebuild(std::size_t slots = 0, bool parallel = false, std::size_t most = 0, bool follow = false);

  // Read-only queries in a context (its locks, its scratch). A locking
  // context takes shared locks and reports rollback on a conflict (holding
  // nothing then); otherwise they are the const queries of Triangulation.
  OpStatus locate(OpContext& ctx, const KPoint& p, VertexId hint, CellId hint_cell, LocateResult& out) const;
  OpStatus nearest_vertex(OpContext& ctx, const KPoint& p, VertexId& out) const;
  // The cell of h if live (*view filled) or dead (*alive = false). Holding
  // h.anchor shared pins every cell around it, so nothing else is locked.
  // Takes h.anchor shared and says whether h's cell is alive; on done the
  // anchor stays held (the caller releases), on rollback nothing is held.
  OpStatus hold_cell(OpContext& ctx, CellHandle h, bool* alive) const;
  // while_held, if given, runs on the cell (if alive) before the anchor is released.
  OpStatus find_cell(OpContext& ctx, CellHandle h, bool* alive, CellView* view,
                     const std::function<void(const CellView&)>* while_held = nullptr) const;
  void fill_view(CellId c, CellView& out) const;

  // -- insertion (insertion.cpp) --------------------------------------------------
  struct Inserted {
    InsertResult result;
    std::uint64_t stamp = 0;  // the incarnation of result.vertex
  };
  // only_if_alive: insert p only if that cell is still live (else do nothing
  // and report {no_vertex, false}); the check and the insertion are one
  // operation, since the cell's anchor stays held in between.
  OpStatus insert(OpContext& ctx, const KPoint& p, VertexId hint, Inserted& out,
                  const CellHandle* only_if_alive = nullptr);
  // The marks it sets are cleared before it returns, but when it is done,
  // the zone's cells keep theirs (in) until cone_from_vertex renews or frees
  // them; a caller that stops before that clears them with clear_zone_marks.
  OpStatus gather_conflict_zone(OpContext& ctx, const KPoint& p, CellId c0, const detail::FilterEps& eps);
  void clear_zone_marks(OpContext& ctx) {
    for (CellId c : ctx.conflict_zone) set_mark(c, 0);
  }
  void cone_from_vertex(OpContext& ctx, VertexId v);
  void link_cone(OpContext& ctx);  // the cone's internal adjacencies (boundary[i].outer = new cell)

  // -- removal (removal.cpp) ------------------------------------------------------
  // expected_stamp: 0 = any; else the vertex must be that incarnation.
  OpStatus remove(OpContext& ctx, VertexId v, std::uint64_t expected_stamp, RemoveResult& out);
  OpStatus remove_3d(OpContext& ctx, VertexId v);
  // A link of at least large_link vertices is put in spatial order before
  // its small triangulation is built (removal.cpp says why).
  static constexpr std::size_t large_link = 256;
  void order_link(OpContext& ctx);
  // The cells incident to v (v held by ctx, shared or exclusively) into out,
  // in order of discovery (ctx.star_seen holds them).
  void collect_star(OpContext& ctx, VertexId v, std::vector<CellId>& out);
  void fill_hole_flat_link(OpContext& ctx, VertexId v);
  void sew_link_triangulation(OpContext& ctx, VertexId v);
  // A link vertex's id in the link triangulation (remove_3d numbered it).
  std::uint32_t small_id(VertexId w) const { return w == 0 ? 0 : verts[w].scratch; }

  // -- dimension < 3 (flat_state.cpp; single-threaded only) ----------------------
  InsertResult insert_flat(OpContext& ctx, const KPoint& p);
  OpStatus remove_flat(OpContext& ctx, VertexId v);  // always done
  void recompute_basis();
  void build_3d(OpContext& ctx, VertexId apex);
  // Removes v, whose removal leaves a coplanar set: every cell goes, the
  // survivors become the flat list. Reserves first: changes nothing if it throws.
  void drop_to_flat(OpContext& ctx, VertexId v);
  VertexId find_flat(const KPoint& p) const { return flat_index.find(p, verts); }

  bool validate(std::string* why) const;  // validate.cpp
  // The distinct edges of the live cells (the infinite vertex's included),
  // counted in passes of about pass_edges (validate.cpp).
  std::size_t count_distinct_edges(std::size_t pass_edges = std::size_t{8} << 20) const;
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
