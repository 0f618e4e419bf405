// SPDX-License-Identifier: MIT
// Dimension < 3: while the live points are coplanar there is no tetrahedron;
// the vertices are kept in a list (with a point index for duplicates) until an
// affinely independent 4th arrives and build_3d makes the first tetrahedron.
// A removal that leaves a coplanar set drops back here. Single-threaded only:
// the engine runs these with the world stopped.
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "fault_injection.hpp"
#include "spatial_order.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::KPoint;
using detail::OpContext;
using detail::OpStatus;
using detail::orient;

InsertResult Triangulation::Impl::insert_flat(OpContext& ctx, const KPoint& p) {
  if (VertexId w = find_flat(p); w != no_vertex) {
    VertexWrite hold(*this, ctx, w);
    ++verts[w].multiplicity;
    ++ctx.stats.duplicates;
    ++ctx.stats.insertions;
    return {w, false};
  }
  const bool raises_to_3d = basis.dimension() == 2 && basis.raises(p);
  if (!raises_to_3d) {
    // Room first: after alloc_vertex nothing may fail.
    PDT_FAULT_POINT("flat list");
    // Growing geometrically: reserve(size() + 1) would reallocate and copy
    // the whole list for every insertion (1M coplanar points: hours).
    if (flat.size() == flat.capacity()) flat.reserve(std::max<std::size_t>(16, 2 * flat.capacity()));
    flat_index.reserve(flat.size() + 1, verts);
    begin_report(ctx, 0, 0);
  }
  VertexId v = alloc_vertex(ctx, p);
  if (raises_to_3d) {
    try {
      build_3d(ctx, v);
    } catch (...) {
      free_vertex(ctx, v);
      throw;
    }
  } else {
    verts[v].cell = static_cast<CellId>(flat.size());
    flat.push_back(v);
    flat_index.insert(v, verts);
    if (basis.offer(v, pt(v))) dim = basis.dimension();
  }
  // Done: counted and folded before the hook hears of it, so a hook that
  // throws leaves the counts true (finish_change folds them either way).
  ++ctx.stats.insertions;
  finish_change(ctx, OpKind::insert, v, verts[v].stamp.load(std::memory_order_relaxed));
  return {v, true};
}

void Triangulation::Impl::recompute_basis() {
  // The flat vertices are coplanar: the basis stops at 3 of them.
  basis.clear();
  for (VertexId v : flat)
    if (basis.offer(v, pt(v)) && basis.dimension() == 2) break;
  dim = basis.dimension();
}

OpStatus Triangulation::Impl::remove_flat(OpContext& ctx, VertexId v) {
  begin_report(ctx, 0, 0);
  std::size_t pos = verts[v].cell;
  flat[pos] = flat.back();
  verts[flat[pos]].cell = static_cast<CellId>(pos);
  flat.pop_back();
  flat_index.erase(v, verts);
  const bool was_basis = basis.contains(v);
  free_vertex(ctx, v);
  if (ctx.last_vertex == no_vertex && !flat.empty()) ctx.last_vertex = flat.back();
  if (was_basis) recompute_basis();
  return OpStatus::done;
}

void Triangulation::Impl::build_3d(OpContext& ctx, VertexId apex) {
  // First tetrahedron: the basis and the apex, positively oriented; then the
  // 4 infinite cells over its facets. Then every other listed vertex is
  // inserted; the result does not depend on that order. The flat list and
  // index stay as they are until the end: if anything fails on the way, the
  // cells made so far go and the flat state is back as it was.
  const int flat_dim = basis.dimension();
  ctx.recording = false;  // the hook hears of the final cells only (below)
  std::vector<VertexId> rest;
  try {
    PDT_FAULT_POINT("first tetrahedron");
    if (flat.size() > 3) rest.reserve(flat.size() - 3);  // the basis is listed; the apex is not
    VertexId t[4] = {basis[0], basis[1], basis[2], apex};
    if (orient(pt(t[0]), pt(t[1]), pt(t[2]), pt(t[3])) < 0) std::swap(t[0], t[1]);
    reserve_cells(ctx, 5);
    CellId all[5];
    all[0] = alloc_cell(ctx);
    std::memcpy(cells[all[0]].v, t, sizeof t);
    ++ctx.d_finite_cells;
    for (int i = 0; i < 4; ++i) {
      all[i + 1] = alloc_cell(ctx);
      VertexId u[4] = {t[0], t[1], t[2], t[3]};
      u[i] = 0;
      // Replacing v_i by a point beyond facet i flips the sign: swap two others.
      std::swap(u[(i + 1) & 3], u[(i + 2) & 3]);
      std::memcpy(cells[all[i + 1]].v, u, sizeof u);
    }
    // Each of the 5 cells is {t0..t3, infinite} less one vertex (cell 0 lacks
    // the infinite one, cell i + 1 lacks t[i]), so any two share the facet
    // without both missing vertices: in cell a it faces b's missing vertex.
    const VertexId missing[5] = {0, t[0], t[1], t[2], t[3]};
    for (int a = 0; a < 5; ++a)
      for (int b = a + 1; b < 5; ++b)
        set_adjacency(all[a], index_of(all[a], missing[b]), all[b], index_of(all[b], missing[a]));
    for (int i = 0; i < 4; ++i) verts[t[i]].cell = all[0];
    dim.store(3, std::memory_order_release);
    std::size_t live_cells = 5;
    for (VertexId v : flat)
      if (v != t[0] && v != t[1] && v != t[2]) rest.push_back(v);
    grid = detail::JumpGrid{};  // it names no vertex of the new cells yet
    // Insert the rest in a batch's order (spatial_order.hpp), each walk
    // starting from the previous vertex: short walks without the jump grid,
    // which must not name a vertex before it is in the triangulation.
    // Usually there is no rest (the 4th point raised the dimension): nothing
    // to sort, nothing to allocate.
    if (!rest.empty()) {
      std::vector<Point3> points;
      points.reserve(rest.size());
      for (VertexId v : rest) points.push_back({pt(v).x(), pt(v).y(), pt(v).z()});
      const std::vector<std::uint32_t> order = detail::spatial_order(points, false);
      VertexId prev = apex;
      for (const std::uint32_t k : order) {
        const VertexId v = rest[k];
        bool outside = false;
        CellId c = walk(ctx, pt(v), finite_cell_of(prev), &outside, filter.eps());  // every vertex is in the box
        gather_conflict_zone(ctx, pt(v), c, filter.eps());
        reserve_cells(ctx, ctx.boundary.size());
        PDT_FAULT_POINT("edge map");
        ctx.new_cell_by_edge.reserve_for(3 * ctx.boundary.size());
        live_cells += ctx.boundary.size() - ctx.conflict_zone.size();
        cone_from_vertex(ctx, v);
        prev = v;
      }
    }
    // What the hook hears: every cell now live, made by this one insertion.
    // Counted as they were made: a removal's small triangulation holds a
    // whole chunk of cell ids, which a scan would visit on every removal.
    assert([&] {
      std::size_t live = 0;
      for (CellId c = 0; c < cells.size(); ++c) live += cell_alive(c);
      return live == live_cells;
    }());
    begin_report(ctx, live_cells, 0);
  } catch (...) {
    // Back to the flat state: no cell, the flat vertices' positions restored.
    const bool recording = ctx.recording;
    ctx.recording = false;
    free_all_cells(ctx);
    ctx.recording = recording;
    for (std::size_t i = 0; i < flat.size(); ++i) verts[flat[i]].cell = static_cast<CellId>(i);
    dim.store(flat_dim, std::memory_order_release);
    grid = detail::JumpGrid{};
    throw;
  }
  if (ctx.recording)
    for (CellId c = 0; c < cells.size(); ++c)
      if (cell_alive(c)) note_created(ctx, c);
  flat.clear();
  flat_index.clear();
  basis.clear();
  fold_counters(ctx);
  // A removal's small triangulation walks from the vertex it inserted last
  // and never grows a grid (grid_note); it is rebuilt per removal, so a grid
  // here would be an allocation per removal.
  if (!is_small) {
    try {
      grid_rebuild();
    } catch (const std::bad_alloc&) {
      grid = detail::JumpGrid{};  // walks start elsewhere; the next growth retries
    }
  }
  ctx.last_vertex = apex;
  recent_vertex.store(apex, std::memory_order_relaxed);
}

void Triangulation::Impl::drop_to_flat(OpContext& ctx, VertexId v) {
  // The live vertices but v are coplanar (or fewer than 4): every cell goes.
  // Cells go back to this context's pool (other pools' free lists stay valid).
  // Room for the flat list first: past it nothing may fail.
  std::size_t survivors = 0, live_cells = 0;
  const std::vector<detail::IdRange> released = released_ranges();  // all free: not read
  detail::for_each_kept(1, verts.size(), released, [&](std::size_t from, std::size_t to) {
    for (std::size_t w = from; w < to; ++w) survivors += w != v && verts[w].multiplicity > 0;
  });
  for (CellId c = 0; c < cells.size(); ++c) live_cells += cell_alive(c);
  PDT_FAULT_POINT("flat list");
  flat.clear();
  flat_index.clear();
  flat.reserve(survivors);
  flat_index.reserve(survivors, verts);
  begin_report(ctx, 0, live_cells);
  free_all_cells(ctx);
  free_vertex(ctx, v);
  grid = detail::JumpGrid{};
  detail::for_each_kept(1, verts.size(), released, [&](std::size_t from, std::size_t to) {
    for (auto w = static_cast<VertexId>(from); w < to; ++w) {
      if (verts[w].multiplicity == 0) continue;
      verts[w].cell = static_cast<CellId>(flat.size());
      flat.push_back(w);
      flat_index.insert(w, verts);
    }
  });
  recompute_basis();
  ctx.last_vertex = flat.empty() ? no_vertex : flat.back();
  recent_vertex.store(no_vertex, std::memory_order_relaxed);
}

}  // namespace pdt
