// SPDX-License-Identifier: MIT
// Triangulation::shrink_to_fit: the storage given back after the mesh shrank.
//
// Freed cell and vertex ids are reused by later insertions, so the storage
// keeps the size of the largest mesh it held. Here, with nothing else running:
//   cells     the live cells move down into the free ids below them (two
//             fingers, as a compacting collector: the lowest free id takes the
//             highest live cell), neighbours and vertices follow, and the
//             array is cut after the last live cell. A moved cell is a new
//             incarnation at its new id; its old id is marked free (I8), so a
//             handle to it reads as dead and one to a cell that stayed still
//             names it. The tags past the cut go too: tag_floor keeps the
//             highest incarnation they held (pools.cpp, reserve_cells).
//   vertices  ids never move (users hold them). The free ids above the
//             last live one are cut off the array (vertex_id_bound() drops;
//             stamps come from a process-wide source, so a handle to an id
//             handed out again still reads as dead). Runs of at least
//             min_released_run free ids below it give their records back
//             (all-zero, as fresh memory) and wait in released_vertices,
//             which later scans over the ids skip; the other free ids make
//             the free list again (a run too, if that list cannot grow:
//             nothing here throws).
//   grid      rebuilt for the vertices there are, if it was built for far more
//             or has far more slots (an engine's); before the vertices go.
#include <algorithm>
#include <cassert>
#include <mutex>
#include <new>
#include <vector>

#include "triangulation_impl.hpp"

namespace pdt {

using detail::no_index;

namespace {
// A run of free vertex ids shorter than this keeps its records: it holds at
// most a page or two, and each released run is a range to hand out again.
constexpr std::uint32_t min_released_run = 256;
}  // namespace

void Triangulation::Impl::shrink_to_fit() {
  assert(!is_small && engine.load() == nullptr);
  OpContext& ctx = *seq;
  fold_counters(ctx);
  ctx.release_large_scratch();
  ctx.small.reset();  // a removal's scratch triangulation: made again by the next one

  // -- cells ------------------------------------------------------------------
  // Every free id is listed anew below: the pools start empty.
  ctx.free_cells = detail::FreeList{};
  ctx.fresh_cell = ctx.fresh_cell_end = 0;
  ctx.reserved_head = ctx.reserved_more = no_index;
  ctx.reserved_cells = 0;
  spare_cells.head.store(no_index, std::memory_order_relaxed);

  const std::size_t old_cells = cells.size();
  // A free id may take a cell unless it is retired (free_cell).
  auto takes_a_cell = [&](CellId c) { return !cell_alive(c) && incarnation(c) < retire_at; };
  // Invariant of the loop: no live cell lies at an id >= hi (each moved below
  // lo), and every id below lo holds a live cell or is retired.
  CellId lo = 0, hi = static_cast<CellId>(old_cells);  // [hi, old_cells) holds no live cell
  for (;;) {
    while (lo < hi && !takes_a_cell(lo)) ++lo;
    while (hi > lo && !cell_alive(hi - 1)) --hi;
    if (lo >= hi) break;
    const CellId from = hi - 1, to = lo;  // to < from: a free id below a live cell
    cells[to] = cells[from];
    renew(to);
    set_mark(from, mark_free);
    cells[from].v[0] = no_vertex;
    cells[from].n[0] = to;  // where it went, for its neighbours and vertices below
    ++lo;
    --hi;
  }
  std::size_t kept = hi;
  while (kept > 0 && !cell_alive(static_cast<CellId>(kept - 1))) --kept;
  if (kept < old_cells) {
    auto moved_to = [&](std::uint32_t c) {
      assert(c < kept || (!cell_alive(c) && cells[c].n[0] < kept));  // only moved cells lie past the cut
      return c < kept ? c : cells[c].n[0];
    };
    // Each live vertex through the cells it is in: the records of vertices
    // given back before are not read (see the jump grid below).
    for (CellId c = 0; c < kept; ++c) {
      if (!cell_alive(c)) continue;
      for (std::uint32_t& n : cells[c].n) n = 4 * moved_to(n >> 2) + (n & 3);
      for (VertexId w : cells[c].v)
        if (w != 0 && verts[w].cell >= kept) verts[w].cell = moved_to(verts[w].cell);
    }
    for (std::size_t c = kept; c < old_cells; ++c) tag_floor = std::max(tag_floor, incarnation(static_cast<CellId>(c)));
    tag_floor_end = std::max(tag_floor_end, old_cells);
    cells.truncate(kept);
    tags.truncate(kept);
  }
  for (CellId c = 0; c < kept; ++c)
    if (takes_a_cell(c)) {
      ++ctx.d_cells;  // free_cell counts a release
      free_cell(ctx, c);
    }

  // -- jump grid --------------------------------------------------------------
  // Before the vertices' records go: its build reads every id's record but
  // those given back before (a kernel without a shared zero page, as in
  // some VMs, commits a page that is read).
  const auto live = static_cast<std::size_t>(n_vertices.load(std::memory_order_relaxed));
  if (dim.load(std::memory_order_relaxed) == 3 && grid_growth == GridGrowth::kernel &&
      (grid.built_for > 2 * live + 64 || grid.slot_count > live + 64)) {  // the kernel's: about live / 2 slots
    try {
      grid_rebuild();
    } catch (const std::bad_alloc&) {
      // The old grid stays: walks from its stale slots still find their way.
    }
  }
  // -- vertices ---------------------------------------------------------------
  ctx.free_vertices = detail::FreeList{};
  ctx.fresh_vertex = ctx.fresh_vertex_end = 0;
  spare_vertices.head.store(no_index, std::memory_order_relaxed);
  // The runs released before are skipped, not read: all free, and reading
  // them could commit their pages again (above).
  std::vector<IdRun> before;
  {
    std::lock_guard lock(spare_mutex);
    before.swap(released_vertices);
    released_vertex_count.store(0, std::memory_order_relaxed);
  }
  std::sort(before.begin(), before.end(), [](IdRun a, IdRun b) { return a.first < b.first; });
  std::size_t next_before = 0;
  // The end of the released run holding id x, or 0; x never decreases.
  auto released_run_end = [&](VertexId x) -> VertexId {
    while (next_before < before.size() && before[next_before].first + before[next_before].count <= x) ++next_before;
    const bool in = next_before < before.size() && before[next_before].first <= x;
    return in ? before[next_before].first + before[next_before].count : 0;
  };
  const auto n_ids = static_cast<VertexId>(verts.size());
  for (VertexId v = 1; v < n_ids;) {
    VertexId end = v;  // [v, end): free ids
    while (end < n_ids) {
      if (const VertexId skip = released_run_end(end)) {
        end = skip;
      } else if (verts[end].multiplicity == 0) {
        ++end;
      } else {
        break;
      }
    }
    if (end == v) {  // v is live
      ++v;
      continue;
    }
    if (end == n_ids) {  // the ids above the last live one go altogether: vertex_id_bound() drops
      verts.truncate(v);
      break;
    }
    bool listed = false;
    if (end - v >= min_released_run) {
      try {
        released_vertices.push_back({v, end - v});  // no engine: nobody else takes the mutex
        listed = true;
      } catch (const std::bad_alloc&) {
        // The run stays on the free list: nothing given back, nothing lost.
      }
    }
    if (listed) {
      verts.zero(v, end);
      released_vertex_count.fetch_add(end - v, std::memory_order_relaxed);
    } else {
      for (VertexId w = v; w < end; ++w) {
        ++ctx.d_vertices;  // free_vertex counts a release
        free_vertex(ctx, w);
      }
    }
    v = end;
  }
  std::reverse(released_vertices.begin(), released_vertices.end());  // the lowest ids are taken first
}

}  // namespace pdt
