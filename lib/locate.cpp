// SPDX-License-Identifier: MIT
// Location (paper §2.1): where a walk starts (a hint, the jump grid, the
// context's last vertex, random probes) and the visibility walk itself; and the
// conflict test both insertion and validation use.
#include "triangulation_impl.hpp"

namespace pdt {

using detail::CellRec;
using detail::KPoint;
using detail::OpContext;
using detail::orient;
using detail::perturbed_incircle;
using detail::OpStatus;
using detail::perturbed_insphere;

CellId Triangulation::Impl::finite_cell_of(VertexId v) const {
  CellId c = verts[v].cell;
  int k = index_of(c, 0);
  if (k >= 0) c = cells[c].n[k] >> 2;  // across the hull facet: finite
  return c;
}

VertexId Triangulation::Impl::start_vertex(OpContext& ctx, const KPoint& p, VertexId hint) const {
  auto usable = [&](VertexId v) {
    return v != no_vertex && v != 0 && v < verts.size() && const_cast<Impl*>(this)->lock_shared(ctx, v) &&
           verts[v].multiplicity > 0;
  };
  if (usable(hint)) return hint;
  if (grid.slot_count) {
    VertexId v = grid.lookup(p);
    if (usable(v)) return v;
  }
  if (usable(ctx.last_vertex)) return ctx.last_vertex;
  // Jump (Mücke et al.): random vertex ids; keep the nearest live one seen.
  const std::size_t bound = verts.size();
  VertexId best = no_vertex;
  for (int probe = 0; probe < 24 && bound > 1; ++probe) {
    auto v = static_cast<VertexId>(1 + ctx.next_random() % (bound - 1));
    if (!usable(v)) continue;
    if (best == no_vertex || CGAL::compare_distance_to_point(p, pt(v), pt(best)) == CGAL::SMALLER) best = v;
  }
  if (best == no_vertex) {
    // One load: the vertex checked (and locked) must be the one returned.
    const VertexId recent = recent_vertex.load(std::memory_order_relaxed);
    if (usable(recent)) best = recent;
  }
  if (best != no_vertex || ctx.locking) return best;  // the engine retries after a rollback
  const std::vector<detail::IdRange> skip = released_ranges();
  detail::for_each_kept(1, bound, skip, [&](std::size_t from, std::size_t to) {
    for (std::size_t v = from; v < to && best == no_vertex; ++v)
      if (verts[v].multiplicity > 0) best = static_cast<VertexId>(v);
  });
  return best;
}

CellId Triangulation::Impl::walk(OpContext& ctx, const KPoint& p, CellId c, bool* outside,
                                 const detail::FilterEps& eps) const {
  // Visibility walk (Devillers, Pion, Teillaud): cross a facet that p is
  // strictly beyond; the facets are tried from a random one so the walk cannot
  // cycle. Never stops in a finite cell that p is outside of.
  Impl& self = *const_cast<Impl*>(this);
  CellId prev = no_cell;
  std::uint64_t r = ctx.next_random();
  while (true) {
    const CellRec& cr = cells[c];
    const KPoint* q[4] = {&pt(cr.v[0]), &pt(cr.v[1]), &pt(cr.v[2]), &pt(cr.v[3])};
    // The next cell is one of these: fetch their records while the
    // orientations wait for the points (cells are scattered in memory).
    for (int i = 0; i < 4; ++i) __builtin_prefetch(&cells[cr.n[i] >> 2]);
    int first = static_cast<int>(r & 3);
    r = (r >> 2) | (r << 62);
    CellId next = no_cell;
    int via = -1;
    for (int k = 0; k < 4; ++k) {
      int i = (first + k) & 3;
      CellId nb = cr.n[i] >> 2;
      if (nb == prev) continue;
      const KPoint* a[4] = {q[0], q[1], q[2], q[3]};
      a[i] = &p;
      if (detail::filtered_orient(*a[0], *a[1], *a[2], *a[3], eps.orient) < 0) {
        next = nb;
        via = i;
        break;
      }
    }
    if (next == no_cell) {
      *outside = false;
      return c;
    }
    // The next cell shares a facet with c, which we hold: it is stable; lock
    // its fourth vertex to hold it.
    if (!self.lock_shared(ctx, cells[next].v[cr.n[via] & 3])) return no_cell;
    ++ctx.stats.walk_steps;
    prev = c;
    c = next;
    if (cell_infinite(c)) {
      *outside = true;
      return c;
    }
  }
}

bool Triangulation::Impl::in_conflict(CellId c, const KPoint& p, const detail::FilterEps& eps) const {
  const CellRec& cr = cells[c];
  int k = index_of(c, 0);
  if (k < 0) return perturbed_insphere(pt(cr.v[0]), pt(cr.v[1]), pt(cr.v[2]), pt(cr.v[3]), p, eps.insphere) > 0;
  // Infinite cell: in conflict when p is beyond its hull facet, or on the
  // facet's plane and inside its (perturbed) circumcircle. The facet order is
  // CGAL's, for which orientation(i0, i1, i2, p) has the sign of the cell with
  // the infinite vertex replaced by p.
  int i0, i1, i2;
  if (k & 1) {
    i0 = (k + 1) & 3, i1 = (k + 2) & 3, i2 = (k + 3) & 3;
  } else {
    i0 = (k + 2) & 3, i1 = (k + 1) & 3, i2 = (k + 3) & 3;
  }
  const KPoint& a = pt(cr.v[i0]);
  const KPoint& b = pt(cr.v[i1]);
  const KPoint& d = pt(cr.v[i2]);
  int o = detail::filtered_orient(a, b, d, p, eps.orient);
  if (o != 0) return o > 0;
  return perturbed_incircle(a, b, d, p) > 0;
}

void Triangulation::Impl::grid_note(OpContext& ctx, VertexId v) {
  if (is_small) return;
  // Resize as the vertex count doubles, or sooner when walks stay long
  // (WalkWatch), unless an engine drives the triangulation: it regrows the
  // grid itself, with the world stopped.
  if (grid_growth == GridGrowth::kernel) {
    const auto live = static_cast<std::size_t>(n_vertices.load(std::memory_order_relaxed) + ctx.d_vertices);
    const bool doubled = live >= 2 * grid.built_for + 64;
    if (doubled || (!ctx.large_batch && grid.grown_since_build(live) &&
                    walk_watch.long_walks(ctx.stats.walk_steps, ctx.stats.insertions))) {
      if (doubled) walk_watch.rearm();
      fold_counters(ctx);
      try {
        grid_rebuild();
      } catch (const std::bad_alloc&) {
        // The insertion is done; walks start from the old grid, which stays.
      }
      return;
    }
  }
  if (grid.slot_count && !ctx.large_batch) grid.set(grid.slot_of(pt(v)), v);
}

void Triangulation::Impl::grid_note_removal(OpContext& ctx) {
  // A removed vertex's slot takes a vertex of its link, but the slots that
  // had taken it from earlier removals keep naming it: as the mesh shrinks
  // most slots come to name dead vertices, and walks start from the last
  // vertex or random probes (48 steps an insertion instead of 6 after 200k
  // vertices were removed down to 2,000). So the grid is rebuilt for the
  // vertices there are once they are a quarter of what it was built for:
  // log4 of the shrinkage rebuilds, each a pass over the vertex ids.
  if (is_small || grid_growth != GridGrowth::kernel || grid.slot_count == 0) return;
  const auto live = static_cast<std::size_t>(std::max<std::int64_t>(0, n_vertices.load(std::memory_order_relaxed) + ctx.d_vertices));
  if (!grid.shrunk_since_build(live)) return;
  walk_watch.rearm();
  fold_counters(ctx);
  try {
    grid_rebuild();
  } catch (const std::bad_alloc&) {
    // The removal is done; walks start from the old grid, which stays.
  }
}

// Holds (shared) a cell containing s and, if that cell is infinite, its
// finite neighbour across the hull facet instead; returns it, or no_cell on a
// conflict.
namespace {
CellId hold_start_cell(const Triangulation::Impl& m, OpContext& ctx, VertexId s) {
  Triangulation::Impl& self = const_cast<Triangulation::Impl&>(m);
  CellId c = m.verts[s].cell;
  for (int i = 0; i < 4; ++i)
    if (!self.lock_shared(ctx, m.cells[c].v[i])) return no_cell;
  if (int k = m.index_of(c, 0); k >= 0) {
    const std::uint32_t nw = m.cells[c].n[k];
    c = nw >> 2;
    if (!self.lock_shared(ctx, m.cells[c].v[nw & 3])) return no_cell;
  }
  return c;
}
}  // namespace

OpStatus Triangulation::Impl::locate(OpContext& ctx, const KPoint& q, VertexId hint, CellId hint_cell,
                                     LocateResult& out) const {
  Impl& self = *const_cast<Impl*>(this);
  out = {};
  if (dim.load(std::memory_order_acquire) < 3) {
    if (ctx.locking) return OpStatus::needs_global;
    VertexId w = find_flat(q);
    if (w != no_vertex) out.vertex = w, out.kind = LocateKind::on_vertex;
    return OpStatus::done;
  }
  auto rollback = [&] {
    self.release_all(ctx);
    return OpStatus::rollback;
  };
  CellId start = no_cell;
  if (!ctx.locking && hint_cell != no_cell && cell_alive(hint_cell)) {
    start = hint_cell;
    if (int k = index_of(start, 0); k >= 0) start = cells[start].n[k] >> 2;
  } else {
    const VertexId s = start_vertex(ctx, q, hint);
    if (s == no_vertex) return rollback();
    start = hold_start_cell(*this, ctx, s);
    if (start == no_cell) return rollback();
  }
  bool outside = false;
  const CellId c = walk(ctx, q, start, &outside, filter.eps_for(q));
  if (c == no_cell) return rollback();
  out.cell = c;
  if (outside) {
    out.kind = LocateKind::outside_hull;
  } else {
    const CellRec& cr = cells[c];
    int zeros = 0;
    for (int i = 0; i < 4; ++i) {
      const KPoint* a[4] = {&pt(cr.v[0]), &pt(cr.v[1]), &pt(cr.v[2]), &pt(cr.v[3])};
      a[i] = &q;
      if (orient(*a[0], *a[1], *a[2], *a[3]) == 0) ++zeros;
      if (pt(cr.v[i]) == q) out.vertex = cr.v[i];
    }
    out.kind = zeros == 0   ? LocateKind::in_cell
               : zeros == 1 ? LocateKind::on_facet
               : zeros == 2 ? LocateKind::on_edge
                            : LocateKind::on_vertex;
  }
  self.release_all(ctx);
  return OpStatus::done;
}

OpStatus Triangulation::Impl::nearest_vertex(OpContext& ctx, const KPoint& q, VertexId& out) const {
  Impl& self = *const_cast<Impl*>(this);
  auto closer = [&](VertexId a, VertexId b) {  // a strictly closer to q than b
    return b == no_vertex || CGAL::compare_distance_to_point(q, pt(a), pt(b)) == CGAL::SMALLER;
  };
  out = no_vertex;
  if (dim.load(std::memory_order_acquire) < 3) {
    if (ctx.locking) return OpStatus::needs_global;
    for (VertexId w : flat)
      if (closer(w, out)) out = w;
    return OpStatus::done;
  }
  auto rollback = [&] {
    self.release_all(ctx);
    return OpStatus::rollback;
  };
  const VertexId s = start_vertex(ctx, q, no_vertex);
  if (s == no_vertex) return rollback();
  const CellId start = hold_start_cell(*this, ctx, s);
  if (start == no_cell) return rollback();
  bool outside = false;
  const CellId c = walk(ctx, q, start, &outside, filter.eps_for(q));
  if (c == no_cell) return rollback();
  VertexId best = no_vertex;
  for (int i = 0; i < 4; ++i) {
    const VertexId w = cells[c].v[i];
    if (w != 0 && closer(w, best)) best = w;
  }
  // Greedy descent on the Delaunay graph ends at the nearest vertex: a vertex
  // with no strictly closer neighbour is a nearest one (its Voronoi cell holds
  // q). Holding best (shared) pins its star, so its neighbours can be read.
  std::vector<CellId>& star = ctx.small_star;
  while (true) {
    self.collect_star(ctx, best, star);
    VertexId next = best;
    for (CellId sc : star)
      for (int i = 0; i < 4; ++i) {
        const VertexId w = cells[sc].v[i];
        if (w != 0 && closer(w, next)) next = w;
      }
    if (next == best) break;
    if (!self.lock_shared(ctx, next)) return rollback();
    best = next;
  }
  out = best;
  self.release_all(ctx);
  return OpStatus::done;
}

OpStatus Triangulation::Impl::hold_cell(OpContext& ctx, CellHandle h, bool* alive) const {
  Impl& self = *const_cast<Impl*>(this);
  *alive = false;
  if (h.mesh != mesh_id) return OpStatus::done;  // another triangulation's (or another life of this object's)
  if (h.anchor == 0 || h.anchor >= verts.size() || h.id >= cells.size()) return OpStatus::done;
  if (!self.lock_shared(ctx, h.anchor)) {
    self.release_all(ctx);
    return OpStatus::rollback;
  }
  // The anchor held, no cell holding it can change. A tag that names h's
  // incarnation, not freed (I8), says h's cell is alive: the operation that
  // destroys it frees or renews its id, holding all its vertices, so it
  // finished before we took the anchor (whose lock ordered its writes before
  // our reads) or cannot start until we let go. The anchor must be one of the
  // cell's vertices, as a report's handle has it; then its record cannot
  // change either. A made-up anchor does not hold the cell, which may be
  // rewritten meanwhile (record_names): but a record being written never
  // names a vertex we hold, old value or new (its writer holds all of both;
  // a freed record names none), so such a handle reads as dead.
  *alive = verts[h.anchor].multiplicity > 0 && dim.load(std::memory_order_acquire) == 3 && h.id < tags.size() &&
           tag_names(h.id, h.incarnation) && record_names(h.id, h.anchor);
  return OpStatus::done;
}

OpStatus Triangulation::Impl::find_cell(OpContext& ctx, CellHandle h, bool* alive, CellView* view,
                                        const std::function<void(const CellView&)>* while_held) const {
  Impl& self = *const_cast<Impl*>(this);
  if (hold_cell(ctx, h, alive) == OpStatus::rollback) return OpStatus::rollback;
  if (*alive) {
    CellView local;
    CellView& out = view ? *view : local;
    fill_view(h.id, out);
    if (while_held && *while_held) {
      try {
        (*while_held)(out);
      } catch (...) {
        self.release_all(ctx);
        throw;
      }
    }
  }
  self.release_all(ctx);
  return OpStatus::done;
}

void Triangulation::Impl::grid_rebuild(std::size_t slots, bool parallel, std::size_t most, bool follow) {
  // Built aside and moved in: an allocation failure leaves the old grid. A
  // tree that follows the vertices for the kernel; equal slots for an
  // engine, whose vertices at a rebuild are those of the blocks done so far,
  // unless 40% of them crowd a few of its slots (a cluster far smaller than
  // the box: walks from there grow with it, 105 steps per insertion for two
  // clusters of side 1e-4 at 200k points), or the engine's walks said the
  // equal slots serve badly (follow). Then the same equal slots with the
  // crowded ones cut again where the vertices are (build_split), in at most
  // twice the slots. (Normal points crowd 30-38%: their walks are 8 steps
  // instead of 6 on equal slots, and a finer grid's rebuilds, the other
  // workers stopped, cost more than that saved: 3% with this cut grid, 3-6%
  // with the kernel's tree built on one thread; line points crowd 45-49%,
  // Kuzmin's 70%, and gain 11-15%.)
  const std::vector<detail::IdRange> skip = released_ranges();
  if (grid_growth == GridGrowth::kernel) {
    grid = detail::JumpGrid::build(verts, slots, skip);
    return;
  }
  if (!follow) {
    detail::JumpGrid equal = detail::JumpGrid::build_equal(verts, slots, parallel, skip);
    if (5 * equal.crowded <= 2 * equal.built_for) {
      grid = std::move(equal);
      return;
    }
  }
  grid = detail::JumpGrid::build_split(verts, slots, std::min(2 * slots, most ? most : 2 * slots), parallel, skip);
}

}  // namespace pdt
