// SPDX-License-Identifier: MIT
#pragma once
// OpContext: everything one thread needs to run kernel operations: its pools,
// its counters, the locks it holds and its scratch. The sequential
// triangulation owns one (locking off); the engine gives each worker one.
// Nothing here is shared between threads.
#include <cstdint>
#include <memory>
#include <vector>

#include "id_map.hpp"
#include "pdt/changes.hpp"
#include "pdt/triangulation.hpp"
#include "storage.hpp"

namespace pdt::detail {

struct OpContext {
  // id: unique among the contexts alive on one triangulation (lock owner);
  // Triangulation::Impl::new_context_id() gives them.
  OpContext(std::uint32_t id, bool locking);
  ~OpContext();
  OpContext(const OpContext&) = delete;
  OpContext& operator=(const OpContext&) = delete;

  const std::uint32_t id;  // 1..; lock owner id
  const bool locking;      // false: single-threaded, every try-lock succeeds
  // The sequential context while an engine owns the triangulation (set by
  // EngineState): its global steps run with no operation beside them, but a
  // thread outside operations may be reading a vertex under a shared lock
  // (read_vertex), so it writes a vertex only holding its lock word
  // (Impl::VertexWrite). Invariant: true only if !locking, or alone.
  bool outside_readers = false;
  // The one context that runs operations (an engine with one worker, whose
  // global steps run while it is paused): no other context reads or writes
  // cells, so its try-locks succeed without touching the lock words, and,
  // as outside_readers says, it writes a vertex holding its word against
  // read_vertex. Invariant: alone implies locking and outside_readers (its
  // operations keep the engine's semantics: needs_global, no flat insertion).
  bool alone = false;
  // The sequential context runs Triangulation::insert_batch of at least as
  // many points as the mesh holds: each walk starts at the vertex made before
  // it, so grid_note does not note the new vertices in the jump grid one by
  // one; the grid is still rebuilt from every vertex as the count doubles.
  // (Engine workers leave it false: measured, no faster there.)
  bool large_batch = false;
  // An insertion's walk: lock_shared takes the words exclusively. The
  // insertion writes the cells around where the walk ends, so most of the
  // walk's shares would be upgraded (a second atomic and a search of
  // held_shared each); taken exclusively once they are not. Set by insert()
  // for its walk only, false between operations.
  bool shares_exclusive = false;

  // -- pools (paper §3.2: per-thread, refilled by chunks) --------------------
  // Invariant: free_cells / free_vertices list ids this context may reuse;
  // [fresh_cell, fresh_cell_end) are ids of its current chunk never used yet.
  FreeList free_cells, free_vertices;
  std::uint32_t fresh_cell = 0, fresh_cell_end = 0;
  // Spare segments taken for a reservation larger than the free list keeps
  // (a cavity of thousands of cells): reserved_cells ids, the segment being
  // used from reserved_head on (linked by the cell list's next), the others
  // stacked from reserved_more (linked by the spare stack's link). Used after
  // the free list, before the fresh range. Invariant: reserved_cells counts
  // exactly the ids reachable that way; 0 iff both heads are no_index.
  std::uint32_t reserved_head = no_index, reserved_more = no_index, reserved_cells = 0;
  std::uint32_t fresh_vertex = 0, fresh_vertex_end = 0;

  // -- counters (net changes, folded into the Impl's totals by fold_counters) -
  std::int64_t d_vertices = 0, d_cells = 0, d_finite_cells = 0;
  TriangulationStats stats;
  // Vertex incarnations: a block [incarnation_next, incarnation_end) drawn from
  // the triangulation's life-long source, so they never repeat.
  std::uint64_t incarnation_next = 0, incarnation_end = 0;
  std::uint64_t insertions_made = 0;  // vertices this context created (paces shared hints)
  std::uint64_t rng;
  // The vertex this context touched last: where its next walk starts when
  // nothing better is known. Kernel-internal; results are returned, not kept here.
  VertexId last_vertex = no_vertex;

  // -- locks held by the current operation ------------------------------------
  std::vector<VertexId> held_shared, held_exclusive;

  // -- scratch of one operation ------------------------------------------------
  // Insertion: the conflict zone (cells whose circumsphere holds the point),
  // its boundary facets, and the new cells by the boundary edge they contain.
  struct BoundaryFacet {
    VertexId v[4];        // the zone cell's vertices; cone_from_vertex: the new cell's (the new vertex first)
    std::uint32_t outer;  // 4*outer cell + mirror facet; cone_from_vertex: then the new cell
    int facet;            // index of the boundary facet in the zone cell
  };
  std::vector<CellId> conflict_zone;
  std::vector<BoundaryFacet> boundary;
  // The cone's internal facets, matched by the boundary edge they contain:
  // with the boundary's n vertices numbered 0..n-1 (0 the infinite
  // vertex's; n <= cone_ids), cone_edge[n * a + b] is 4 * new cell + facet
  // for the facet that sees the directed edge (a, b); larger cones use the map.
  static constexpr std::uint32_t cone_ids = 64;
  std::vector<std::uint32_t> cone_edge;
  IdMap new_cell_by_edge;
  // Removal: the hole (the removed vertex's star), its boundary facets keyed by
  // small-id triple, and the link triangulation that refills it.
  std::vector<CellId> hole;
  IdMap hole_facet_by_triple;
  IdMap star_seen;                   // cells met by collect_star
  // Finite link vertices, in small-id order: small id = index + 1, kept in
  // the vertex's scratch word while the removal holds it (Impl::small_id).
  std::vector<VertexId> link;
  std::vector<std::uint32_t> small_facet_boundary;  // 4*small cell + facet -> boundary index or no_index
  std::vector<CellId> small_inside;  // small cells inside the hole
  std::vector<CellId> small_to_new;  // small cell -> the new big cell sewn in for it
  std::vector<CellId> small_star;
  std::vector<std::uint32_t> small_seen;  // small cell -> flood generation that reached it
  std::uint32_t small_generation = 0;
  std::unique_ptr<Triangulation::Impl> small;  // a removal's link triangulation

  // -- change reporting (changes.hpp) -------------------------------------------
  // Set by the context's owner: the triangulation's hook for the sequential
  // context, the engine's for its workers (and for the sequential context
  // while the engine is attached).
  const ChangeHook* hook = nullptr;
  bool report_destroyed = false;
  bool recording = false;              // the current operation records its changes
  bool in_hook = false;                // *hook is running (the sequential context: mutators refuse)
  std::vector<CellId> created;         // cells the current operation made
  std::vector<CellHandle> destroyed;   // cells it deleted (when report_destroyed)
  std::vector<CellView> views;         // the report's cells
  // Between operations: scratch that an unusually large operation grew past
  // scratch_kept entries (a cavity of a point inside thousands of cospherical
  // points, the link of its removal) is freed, so that what a context keeps
  // follows the live mesh, not the largest operation it ever ran: 16 workers
  // that each met one such cavity kept about 15 MB apiece. Only operations
  // that large pay for the allocations again, in proportion to their work.
  // Never during an operation: the scratch holds its state (pools.cpp).
  static constexpr std::size_t scratch_kept = std::size_t{1} << 14;
  void release_large_scratch();
  // Calls release_large_scratch when it goes out of scope, however the
  // operation (or attempt) it guards ends.
  struct ReleaseLargeScratchAfter {
    OpContext& ctx;
    ~ReleaseLargeScratchAfter() { ctx.release_large_scratch(); }
  };
  std::uint64_t next_random() {
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return rng;
  }
};

}  // namespace pdt::detail
