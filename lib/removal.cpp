// SPDX-License-Identifier: MIT
// Removal (paper §2.2): the hole is the vertex's star; the link's vertices
// are triangulated in a per-context "small" triangulation, whose cells inside
// the hole are sewn in. The symbolic perturbation guarantees that the small
// triangulation contains every boundary facet of the hole.
#include <algorithm>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "fault_injection.hpp"
#include "pdt/error.hpp"
#include "spatial_order.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::CellRec;
using detail::facet_vertex;
using detail::KPoint;
using detail::no_index;
using detail::OpContext;
using detail::OpStatus;

namespace {

// Unordered triple of small ids (< 2^21) packed into one key.
std::uint64_t triple_key(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  if (a > b) std::swap(a, b);
  if (b > c) std::swap(b, c);
  if (a > b) std::swap(a, b);
  return (std::uint64_t{a} << 42) | (std::uint64_t{b} << 21) | c;
}

}  // namespace

OpStatus Triangulation::Impl::remove(OpContext& ctx, VertexId v, std::uint64_t expected_stamp, RemoveResult& out) {
  if (v == 0 || v >= verts.size()) {
    std::ostringstream os;
    if (v == 0)
      os << "cannot remove the infinite vertex (id 0)";
    else
      os << "cannot remove vertex " << v << ": no such vertex was ever inserted";
    throw Error(ErrorCode::unknown_vertex, os.str());
  }
  if (!lock_exclusive(ctx, v)) return OpStatus::rollback;
  if (verts[v].multiplicity == 0 || (expected_stamp && verts[v].stamp.load(std::memory_order_relaxed) != expected_stamp)) {
    release_all(ctx);
    std::ostringstream os;
    if (expected_stamp)  // a handle, an undo, or an engine's removal pinned at submission: it was in once
      os << "cannot remove vertex " << v
         << ": the incarnation of it this removal names was already removed (a stale handle, or another "
            "removal ran first)";
    else
      os << "cannot remove vertex " << v << ": it is not in the triangulation (already removed, or never inserted)";
    throw Error(ErrorCode::unknown_vertex, os.str());
  }
  if (verts[v].multiplicity > 1) {
    {
      VertexWrite hold(*this, ctx, v);
      --verts[v].multiplicity;
    }
    ++ctx.stats.removals;
    release_all(ctx);
    out = RemoveResult::multiplicity_lowered;
    return OpStatus::done;
  }
  const std::uint64_t incarnation = verts[v].stamp.load(std::memory_order_relaxed);
  if (dim.load(std::memory_order_acquire) < 3 && ctx.locking) {
    release_all(ctx);
    return OpStatus::needs_global;
  }
  // Until the first change, a failure (a rollback, a failed allocation)
  // releases what is held and changes nothing.
  try {
    const OpStatus s = dim.load(std::memory_order_acquire) < 3 ? remove_flat(ctx, v) : remove_3d(ctx, v);
    if (s != OpStatus::done) {
      release_all(ctx);
      return s;
    }
  } catch (...) {
    release_all(ctx);
    throw;
  }
  ++ctx.stats.removals;
  out = RemoveResult::removed;
  finish_change(ctx, OpKind::remove, v, incarnation);
  return OpStatus::done;
}

void Triangulation::Impl::collect_star(OpContext& ctx, VertexId v, std::vector<CellId>& out) {
  // The visited set is the context's own, not `marks`: holding v keeps these
  // cells from changing, but not from being marked by an insertion next door
  // that holds a facet of one of them (opposite v) and tests it for conflict.
  detail::IdMap& seen = ctx.star_seen;
  seen.clear();
  out.clear();
  CellId c0 = verts[v].cell;
  seen.get_or_insert(c0, 0);
  out.push_back(c0);
  for (std::size_t idx = 0; idx < out.size(); ++idx) {
    CellId c = out[idx];
    for (int i = 0; i < 4; ++i) {
      if (cells[c].v[i] == v) continue;
      CellId nb = cells[c].n[i] >> 2;  // facet i contains v
      bool inserted = false;
      seen.get_or_insert(nb, 0, &inserted);
      if (inserted) {
        // Fetched while the cells queued before it are read: the star's
        // cells are scattered in memory, and this walk is their first touch.
        __builtin_prefetch(&cells[nb]);
        out.push_back(nb);
      }
    }
  }
}

// A large link (a vertex at the centre of many cospherical points, a dense
// cluster's hub) goes into the small triangulation in spatial order, as a
// batch would, rather than in the order the star met it: 20k points on a
// sphere, their centre removed, took 0.75-1.2 s to triangulate in the met
// order and 0.28 s sorted. The small ids follow the new order. (Allocates:
// a rare path; the usual link of a few dozen vertices stays as met.)
void Triangulation::Impl::order_link(OpContext& ctx) {
  std::vector<Point3> points(ctx.link.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const KPoint& p = pt(ctx.link[i]);
    points[i] = {p.x(), p.y(), p.z()};
  }
  PDT_FAULT_POINT("link order");
  const std::vector<std::uint32_t> order = detail::spatial_order(points, false);
  std::vector<VertexId> sorted(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) sorted[i] = ctx.link[order[i]];
  std::copy(sorted.begin(), sorted.end(), ctx.link.begin());
  for (std::size_t i = 0; i < ctx.link.size(); ++i) verts[ctx.link[i]].scratch = static_cast<std::uint32_t>(i + 1);
}

OpStatus Triangulation::Impl::remove_3d(OpContext& ctx, VertexId v) {
  // v is held exclusively, so every cell incident to v is stable.
  std::vector<CellId>& hole = ctx.hole;
  collect_star(ctx, v, hole);
  // The link: the hole's vertices but v. Finite ones get small ids 1, 2, ...
  // in the order met (their ids in the small triangulation; small_id); the
  // infinite vertex is 0 in both. A link vertex's small id is kept in its
  // scratch word, which is ours once we hold the vertex: it is numbered iff
  // its scratch names its own place in `link` (stale scratch cannot, since
  // `link` lists only vertices numbered here).
  ctx.link.clear();
  for (CellId c : hole)  // the records are scattered: fetch them all at once
    for (VertexId w : cells[c].v) __builtin_prefetch(&verts[w]);
  for (CellId c : hole) {
    const CellRec& r = cells[c];
    for (int i = 0; i < 4; ++i) {
      VertexId w = r.v[i];
      if (w == v || w == 0) continue;
      if (!lock_exclusive(ctx, w)) return OpStatus::rollback;  // already ours: one load
      std::uint32_t& s = verts[w].scratch;
      if (s == 0 || s > ctx.link.size() || ctx.link[s - 1] != w) {
        if (ctx.link.size() == ctx.link.capacity()) PDT_FAULT_POINT("link");
        ctx.link.push_back(w);
        s = static_cast<std::uint32_t>(ctx.link.size());
      }
    }
  }
  // Only now, holding the link, may the hole's outer adjacencies be read: an
  // operation next door rewrites them holding just the shared facet.
  bool outer_all_infinite = true;
  for (CellId c : hole)
    if (!cell_infinite(cells[c].n[index_of(c, v)] >> 2)) outer_all_infinite = false;
  ctx.stats.cells_touched_by_remove += hole.size();

  // Does the removal leave a coplanar set (no tetrahedron at all)? Only when
  // no finite cell lies outside the hole: then the survivors are the link.
  if (outer_all_infinite) {
    detail::AffineBasis survivors;
    for (VertexId w : ctx.link)
      if (survivors.offer(w, pt(w)) && survivors.dimension() == 3) break;
    if (survivors.dimension() < 3) {
      if (ctx.locking) return OpStatus::needs_global;
      drop_to_flat(ctx, v);
      return OpStatus::done;
    }
  }

  // The small triangulation of the link's finite vertices (paper §2.2). The
  // perturbation makes it contain every facet of the hole's boundary.
  if (!ctx.small) {
    PDT_FAULT_POINT("link triangulation");
    ctx.small = std::make_unique<Impl>(true);
  }
  Impl& s = *ctx.small;
  s.clear();
  if (ctx.link.size() >= large_link) order_link(ctx);
  Inserted ignored;
  for (VertexId w : ctx.link) s.insert(*s.seq, pt(w), s.seq->last_vertex, ignored);
  ctx.stats.cells_touched_by_remove += static_cast<std::uint64_t>(s.n_cells.load());

  if (s.dim < 3) {
    begin_report(ctx, hole.size(), hole.size());  // the last step that may fail
    fill_hole_flat_link(ctx, v);
  } else {
    sew_link_triangulation(ctx, v);
  }

  // v's slot and the next walk start at a finite vertex of its link.
  VertexId heir = ctx.link.front();
  for (VertexId w : ctx.link)
    if (w != 0) {
      heir = w;
      break;
    }
  if (grid.slot_count) {
    std::size_t slot = grid.slot_of(pt(v));
    if (grid.get(slot) == v) grid.set(slot, heir);
  }
  free_vertex(ctx, v);
  ctx.last_vertex = heir;
  grid_note_removal(ctx);
  return OpStatus::done;
}

void Triangulation::Impl::fill_hole_flat_link(OpContext& ctx, VertexId v) {
  // v is a hull vertex whose finite link lies in a plane P: after removal the
  // hull is flat on v's side, and the hole is filled by infinite cells over
  // the (unchanged) triangles of P. A finite hole cell becomes such a cell by
  // putting the infinite vertex in v's place; v was beyond P, so orientation
  // is preserved. The infinite hole cells disappear; their outer neighbours
  // become the new cells' neighbours.
  const std::vector<CellId>& hole = ctx.hole;
  for (CellId h : hole) {
    if (cell_infinite(h)) continue;
    // The cell changes: a new incarnation, so a handle to the old one is stale.
    note_destroyed(ctx, h);
    cells[h].v[index_of(h, v)] = 0;
    renew(h);
    note_created(ctx, h);
    --ctx.d_finite_cells;
  }
  for (CellId h : hole) {
    if (index_of(h, v) >= 0) continue;  // a dying infinite cell (it still holds v)
    int k = index_of(h, 0);
    for (int j = 0; j < 4; ++j) {
      if (j == k) continue;
      CellId nb = cells[h].n[j] >> 2;
      int kv = index_of(nb, v);
      if (kv < 0) continue;  // a converted hole cell
      std::uint32_t outer = cells[nb].n[kv];
      set_adjacency(h, j, outer >> 2, static_cast<int>(outer & 3));
    }
    for (int j = 0; j < 4; ++j) set_vertex_cell(cells[h].v[j], h);
  }
  for (CellId h : hole)
    if (index_of(h, v) >= 0) {
      note_destroyed(ctx, h);
      free_cell(ctx, h);
    }
}

void Triangulation::Impl::sew_link_triangulation(OpContext& ctx, VertexId v) {
  Impl& s = *ctx.small;
  OpContext& sctx = *s.seq;
  const std::vector<CellId>& hole = ctx.hole;
  // Boundary facets of the hole, keyed by their unordered small-id triple.
  ctx.boundary.clear();
  detail::IdMap& facets = ctx.hole_facet_by_triple;
  PDT_FAULT_POINT("hole facets");
  facets.reserve_for(hole.size());
  facets.clear();
  ctx.boundary.reserve(hole.size());
  for (CellId h : hole) {
    int k = index_of(h, v);
    OpContext::BoundaryFacet bf;
    std::memcpy(bf.v, cells[h].v, sizeof bf.v);
    bf.outer = cells[h].n[k];
    bf.facet = k;
    std::uint32_t a = small_id(bf.v[facet_vertex[k][0]]);
    std::uint32_t b = small_id(bf.v[facet_vertex[k][1]]);
    std::uint32_t c = small_id(bf.v[facet_vertex[k][2]]);
    facets.get_or_insert(triple_key(a, b, c), static_cast<std::uint32_t>(ctx.boundary.size()));
    ctx.boundary.push_back(bf);
  }
  // A small cell on the inner side of the first boundary facet: it lists the
  // facet in the same cyclic order as the hole cell does.
  const OpContext::BoundaryFacet& f0 = ctx.boundary.front();
  std::uint32_t t0[3];
  for (int j = 0; j < 3; ++j) t0[j] = small_id(f0.v[facet_vertex[f0.facet][j]]);
  s.collect_star(sctx, t0[0] != 0 ? t0[0] : t0[1], ctx.small_star);
  CellId start = no_cell;
  for (CellId sc : ctx.small_star) {
    for (int m = 0; m < 4 && start == no_cell; ++m) {
      std::uint32_t u[3];
      for (int j = 0; j < 3; ++j) u[j] = s.cells[sc].v[facet_vertex[m][j]];
      for (int r = 0; r < 3; ++r)
        if (u[r] == t0[0] && u[(r + 1) % 3] == t0[1] && u[(r + 2) % 3] == t0[2]) start = sc;
    }
    if (start != no_cell) break;
  }
  if (start == no_cell) throw std::logic_error("pdt: removal: a hole facet is missing from the link triangulation");

  // Flood the small triangulation from there, stopping at boundary facets:
  // the cells reached fill the hole exactly.
  std::vector<CellId>& inside = ctx.small_inside;
  inside.clear();
  std::size_t small_bound = s.cells.size();
  PDT_FAULT_POINT("sewing scratch");
  if (ctx.small_facet_boundary.size() < 4 * small_bound) ctx.small_facet_boundary.resize(4 * small_bound);
  if (ctx.small_to_new.size() < small_bound) ctx.small_to_new.resize(small_bound);
  if (ctx.small_seen.size() < small_bound) ctx.small_seen.resize(small_bound, 0);
  inside.reserve(small_bound);
  if (++ctx.small_generation == 0) {  // wrapped: forget every old generation
    std::fill(ctx.small_seen.begin(), ctx.small_seen.end(), 0);
    ctx.small_generation = 1;
  }
  const std::uint32_t seen = ctx.small_generation;
  ctx.small_seen[start] = seen;
  inside.push_back(start);
  std::size_t matched = 0;
  for (std::size_t idx = 0; idx < inside.size(); ++idx) {
    CellId sc = inside[idx];
    const CellRec& r = s.cells[sc];
    for (int m = 0; m < 4; ++m) {
      std::uint32_t b = facets.find(triple_key(r.v[facet_vertex[m][0]], r.v[facet_vertex[m][1]], r.v[facet_vertex[m][2]]));
      ctx.small_facet_boundary[4 * sc + m] = b;
      if (b != no_index) {
        ++matched;
        continue;
      }
      CellId nb = r.n[m] >> 2;
      if (ctx.small_seen[nb] != seen) {
        ctx.small_seen[nb] = seen;
        inside.push_back(nb);
      }
    }
  }
  if (matched != ctx.boundary.size())
    throw std::logic_error("pdt: removal: the link triangulation does not match the hole");
  reserve_cells(ctx, inside.size());
  begin_report(ctx, inside.size(), hole.size());  // the last step that may fail

  // Sew: hole cells out, the inside small cells in, with big vertex ids.
  for (CellId h : hole) {
    if (!cell_infinite(h)) --ctx.d_finite_cells;
    note_destroyed(ctx, h);
    free_cell(ctx, h);
  }
  for (CellId sc : inside) {
    ctx.small_to_new[sc] = alloc_cell(ctx);
    note_created(ctx, ctx.small_to_new[sc]);
  }
  for (CellId sc : inside) {
    CellId nc = ctx.small_to_new[sc];
    const CellRec& r = s.cells[sc];
    bool finite = true;
    for (int j = 0; j < 4; ++j) {
      VertexId sv = r.v[j];
      VertexId bv = sv == 0 ? 0 : ctx.link[sv - 1];
      cells[nc].v[j] = bv;
      set_vertex_cell(bv, nc);
      if (bv == 0) finite = false;
    }
    if (finite) ++ctx.d_finite_cells;
    for (int m = 0; m < 4; ++m) {
      std::uint32_t b = ctx.small_facet_boundary[4 * sc + m];
      if (b != no_index) {
        std::uint32_t outer = ctx.boundary[b].outer;
        set_adjacency(nc, m, outer >> 2, static_cast<int>(outer & 3));
      } else {
        std::uint32_t sn = r.n[m];
        cells[nc].n[m] = 4 * ctx.small_to_new[sn >> 2] + (sn & 3);
      }
    }
  }
  ctx.stats.cells_created_by_remove += inside.size();
}

}  // namespace pdt
