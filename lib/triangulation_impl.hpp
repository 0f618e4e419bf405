#pragma once
// The data structure behind pdt::Triangulation.
//
// Storage (index based, never moves; see stable_array.hpp):
//   cells[c].v[i]  vertex i of cell c. Vertex 0 is the infinite vertex.
//   cells[c].n[i]  4 * d + j: cell d shares c's facet i (the facet opposite
//                  v[i]) and that facet is d's facet j. So following an
//                  adjacency and finding the mirror facet is one load.
//   marks[c]       visit stamp of the last cavity search that touched c. A stamp
//                  is (context id << 48 | counter), so searches of different
//                  threads, or earlier ones of the same thread, never match.
//                  Only a thread holding a facet of c exclusively writes marks[c]
//                  (two such threads would share a vertex), so a cavity search
//                  owns the marks it reads.
//   verts[v]       point, one incident cell, multiplicity, lock word, stamp.
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
// facet's vertices), which lets a walk or a cavity search read one step ahead.
// verts[0].cell is never read or written (it would be a point of contention).
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "pdt/triangulation.hpp"
#include "predicates.hpp"
#include "stable_array.hpp"

namespace pdt {
namespace detail {

struct CellRec {
  VertexId v[4];
  std::uint32_t n[4];
};

struct VertexRec {
  KPoint p;
  CellId cell = no_cell;
  std::uint32_t multiplicity = 0;
  std::atomic<std::int32_t> lock{0};
  // Unique per vertex incarnation (context << 40 | counter); 0 when free.
  // Atomic so that a thread submitting a removal can read it without a lock:
  // it is stored (release) after p on allocation, cleared on release.
  std::atomic<std::uint64_t> stamp{0};
};

// Facet i of a cell, its vertices ordered so that every facet is seen with the
// same handedness from its cell: two cells sharing a facet list it in opposite
// cyclic orders.
inline constexpr int facet_vertex[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};

// uint64 -> uint32 open-addressing map, cleared in O(entries used). Scratch for
// one operation: no allocation once warmed up.
class IdMap {
 public:
  void clear();
  // Returns the value for key, inserting `value` if absent (then *inserted = true).
  std::uint32_t get_or_insert(std::uint64_t key, std::uint32_t value, bool* inserted = nullptr);
  std::uint32_t find(std::uint64_t key) const;  // 0xFFFFFFFF if absent
  void reserve_for(std::size_t entries);

 private:
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::vector<std::uint32_t> used_;
  std::size_t mask_ = 0;
};

// Jump-and-walk start (paper §2.1, Mücke et al.), structured: a uniform grid
// over the points' bounding box remembers, per slot, the last vertex inserted
// there. Locating starts at the vertex of p's slot (or the nearest filled slot),
// so walks stay short. Slots are relaxed atomics: a slot may name a vertex that
// has since died or been recycled, so a reader checks the vertex (under its
// lock, in the engine) before using it.
struct JumpGrid {
  double lo[3] = {0, 0, 0};
  double inv[3] = {0, 0, 0};
  int res = 0;
  std::unique_ptr<std::atomic<VertexId>[]> slots;
  std::size_t slot_count = 0;
  std::size_t built_for = 0;
  std::size_t slot_of(const KPoint& p) const;
  VertexId get(std::size_t s) const { return slots[s].load(std::memory_order_relaxed); }
  void set(std::size_t s, VertexId v) { slots[s].store(v, std::memory_order_relaxed); }
};

// What an operation of the kernel ended with.
enum class OpStatus {
  done,
  rollback,     // met a lock held by another thread; nothing was changed
  needs_global  // would change the dimension: must run with the world stopped
};

// A singly linked free list of cell or vertex ids threaded through the records.
struct FreeList {
  std::uint32_t head = 0xFFFFFFFFu;
  std::uint32_t tail = 0xFFFFFFFFu;
  std::size_t count = 0;
};

}  // namespace detail



// Everything one thread needs to run operations: its pools, its scratch and
// the locks it holds. The sequential triangulation owns one (locking off);
// the engine gives each worker one. Nothing here is shared between threads.
struct OpContext {
  OpContext(std::uint32_t id, bool locking);
  ~OpContext();
  OpContext(const OpContext&) = delete;
  OpContext& operator=(const OpContext&) = delete;

  const std::uint32_t id;  // 1..; lock owner id and stamp prefix
  const bool locking;      // false: single-threaded, every try-lock succeeds

  // -- pools (paper §3.2: per-thread, refilled by chunks) --------------------
  detail::FreeList free_cells, free_vertices;
  std::uint32_t fresh_cell = 0, fresh_cell_end = 0;      // unused ids of the current cell chunk
  std::uint32_t fresh_vertex = 0, fresh_vertex_end = 0;  // same for vertices

  // -- counters (net changes, folded into the Impl's totals: end_op_counters) -
  std::int64_t d_vertices = 0, d_cells = 0, d_finite_cells = 0;
  TriangulationStats stats;
  std::uint64_t stamp_counter = 0, vertex_counter = 0;
  std::uint64_t rng;
  VertexId last_vertex = no_vertex;
  std::uint64_t result_stamp = 0;  // stamp of the vertex the last insert() returned

  // -- locks held by the current operation ------------------------------------
  std::vector<VertexId> held_shared, held_exclusive;

  // -- scratch ---------------------------------------------------------------
  struct BoundaryFacet {
    VertexId v[4];        // the new cell's vertices
    std::uint32_t outer;  // 4*outer cell + mirror facet
    int facet;            // index of the boundary facet in the new cell
  };
  std::vector<CellId> cavity;
  std::vector<BoundaryFacet> boundary;
  detail::IdMap facet_map;
  detail::IdMap visited;             // cells met by collect_incident_cells
  std::vector<VertexId> link;        // finite vertices of a hole but v, in small-id order
  detail::IdMap link_index;          // big id -> small id (0 for the infinite vertex)
  std::vector<std::uint32_t> small_facet_bf;
  std::vector<CellId> small_inside;
  std::vector<CellId> small_to_new;
  std::vector<CellId> star;
  std::unique_ptr<Triangulation::Impl> small;  // a removal's link triangulation

  std::uint64_t next_stamp() { return (std::uint64_t{id} << 48) | (stamp_counter += 2); }
  std::uint64_t next_random() {
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return rng;
  }
};

struct Triangulation::Impl {
  using CellRec = detail::CellRec;
  using VertexRec = detail::VertexRec;
  using KPoint = detail::KPoint;
  using OpStatus = detail::OpStatus;

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
  std::array<VertexId, 3> basis{no_vertex, no_vertex, no_vertex};

  const bool is_small;  // a removal's scratch triangulation: no jump grid
  detail::JumpGrid grid;
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

  CellId alloc_cell(OpContext& ctx);
  void free_cell(OpContext& ctx, CellId c);
  VertexId alloc_vertex(OpContext& ctx, const KPoint& p);
  void free_vertex(OpContext& ctx, VertexId v);
  // Gives a context's pooled ids back to another context (engine shutdown).
  void merge_pools(OpContext& into, OpContext& from);
  void fold_counters(OpContext& ctx);
  void end_op_counters(OpContext& ctx);  // folds now, or later for an engine worker

  // -- locks (no-ops when !ctx.locking) ----------------------------------------
  bool lock_shared(OpContext& ctx, VertexId v);
  bool lock_exclusive(OpContext& ctx, VertexId v);  // upgrades a shared lock we hold
  bool lock_cell_exclusive(OpContext& ctx, CellId c);
  void release_all(OpContext& ctx);

  // -- operations (the context's own; Triangulation's API uses `seq`) ---------
  OpStatus insert(OpContext& ctx, const KPoint& p, VertexId hint, InsertResult& out);
  // expected_stamp: 0 = any; else the vertex must be that incarnation.
  OpStatus remove(OpContext& ctx, VertexId v, std::uint64_t expected_stamp, RemoveResult& out);
  void clear();

  // Location: the cell where a visibility walk from `start` ends: a finite
  // cell whose closure contains p, or an infinite cell whose hull facet p is
  // strictly beyond (then *outside = true). Locks shared as it goes;
  // no_cell means a rollback.
  CellId walk(OpContext& ctx, const KPoint& p, CellId start, bool* outside) const;
  VertexId start_vertex(OpContext& ctx, const KPoint& p, VertexId hint) const;
  CellId finite_cell_of(VertexId v) const;
  bool in_conflict(CellId c, const KPoint& p) const;

  // dimension < 3 (single-threaded only)
  InsertResult insert_flat(OpContext& ctx, const KPoint& p);
  void remove_flat(OpContext& ctx, VertexId v);
  void recompute_basis();
  void build_3d(OpContext& ctx, VertexId apex);
  void drop_to_flat(OpContext& ctx);
  static std::uint64_t point_hash(const KPoint& p);
  VertexId find_flat(const KPoint& p) const;

  // dimension 3
  OpStatus find_cavity(OpContext& ctx, const KPoint& p, CellId c0);
  void fill_cavity(OpContext& ctx, VertexId v);
  OpStatus remove_3d(OpContext& ctx, VertexId v);
  void collect_incident_cells(OpContext& ctx, VertexId v, std::vector<CellId>& out);
  void fill_hole_flat_link(OpContext& ctx, VertexId v);
  void fill_hole(OpContext& ctx, VertexId v);

  void grid_update(OpContext& ctx, VertexId v);
  VertexId grid_lookup(const KPoint& p) const;
  // Rebuilds the jump grid over the live vertices' bounding box, with about
  // `slots` slots when given (the engine's capped size), else n/2.
  void grid_rebuild(std::size_t slots = 0);

  bool validate(std::string* why) const;
};

}  // namespace pdt
