// SPDX-License-Identifier: MIT
// Insertion (paper §2.1): Bowyer-Watson. Locate p, gather the conflict zone
// (the cells whose perturbed circumsphere holds p), and replace it by the cone
// from the new vertex over the zone's boundary.
#include <array>
#include <cassert>
#include <cstring>

#include "fault_injection.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::CellRec;
using detail::KPoint;
using detail::OpContext;
using detail::OpStatus;

namespace {

std::uint64_t edge_key(VertexId a, VertexId b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t{a} << 32) | b;
}

}  // namespace

OpStatus Triangulation::Impl::insert(OpContext& ctx, const KPoint& p, VertexId hint, Inserted& out,
                                     const CellHandle* only_if_alive) {
  // The filter's box holds every vertex (box_filter.hpp). An engine's domain
  // is in it from the start and the engine refuses points outside it, so its
  // workers, which read the box, never see it grow: a point outside would be
  // added by a global step, with the world stopped. (First: nothing is held.)
  if (!filter.contains(p)) {
    if (ctx.locking) return OpStatus::needs_global;
    filter.extend(p);
  }
  const detail::FilterEps eps = filter.eps();
  if (only_if_alive) {
    // No cell lives below dimension 3; otherwise the cell's anchor, held from
    // here on, keeps it as it is until the insertion is done.
    bool alive = false;
    if (dim.load(std::memory_order_acquire) == 3 && hold_cell(ctx, *only_if_alive, &alive) == OpStatus::rollback)
      return OpStatus::rollback;
    if (!alive) {
      release_all(ctx);
      out = {};
      return OpStatus::done;
    }
    hint = only_if_alive->anchor;  // and a walk start next to it
  }
  if (dim.load(std::memory_order_acquire) < 3) {
    if (ctx.locking) return OpStatus::needs_global;
    out.result = insert_flat(ctx, p);  // counts, folds and reports
    out.stamp = verts[out.result.vertex].stamp.load(std::memory_order_relaxed);
    out.result.incarnation = out.stamp;
    return OpStatus::done;
  }
  auto rollback = [&] {
    release_all(ctx);
    return OpStatus::rollback;
  };
  VertexId s = start_vertex(ctx, p, hint);
  if (s == no_vertex) return rollback();
  // Hold s's cell (stable: it contains s, which we hold), then walk, taking
  // exclusively what the walk locks (OpContext::shares_exclusive).
  struct WalkLocks {
    OpContext& ctx;
    explicit WalkLocks(OpContext& c) : ctx(c) { ctx.shares_exclusive = ctx.locking; }
    ~WalkLocks() { ctx.shares_exclusive = false; }
  } walk_locks(ctx);
  CellId c = verts[s].cell;
  for (int i = 0; i < 4; ++i)
    if (!lock_shared(ctx, cells[c].v[i])) return rollback();
  if (int k = index_of(c, 0); k >= 0) {
    std::uint32_t nw = cells[c].n[k];
    c = nw >> 2;
    if (!lock_shared(ctx, cells[c].v[nw & 3])) return rollback();
  }
  bool outside = false;
  c = walk(ctx, p, c, &outside, eps);
  ctx.shares_exclusive = false;
  if (c == no_cell) return rollback();
  if (!outside) {
    const CellRec& cr = cells[c];
    for (int i = 0; i < 4; ++i) {
      VertexId w = cr.v[i];
      if (w != 0 && pt(w) == p) {
        if (!lock_exclusive(ctx, w)) return rollback();
        {
          VertexWrite hold(*this, ctx, w);
          ++verts[w].multiplicity;
        }
        out.stamp = verts[w].stamp.load(std::memory_order_relaxed);
        ++ctx.stats.duplicates;
        ++ctx.stats.insertions;
        release_all(ctx);
        out.result = {w, false, out.stamp};
        return OpStatus::done;
      }
    }
  }
  if (!lock_cell_exclusive(ctx, c)) return rollback();
  if (gather_conflict_zone(ctx, p, c, eps) != OpStatus::done) return rollback();
  // Everything the change needs, before its first write: cells, map room,
  // report room, the vertex (a fresh chunk of ids may fail to come: the
  // zone's marks must go then too). A failure here changes nothing.
  VertexId v = no_vertex;
  try {
    reserve_cells(ctx, ctx.boundary.size());
    PDT_FAULT_POINT("edge map");
    ctx.new_cell_by_edge.reserve_for(3 * ctx.boundary.size());
    begin_report(ctx, ctx.boundary.size(), ctx.conflict_zone.size());
    v = alloc_vertex(ctx, p);
  } catch (...) {
    clear_zone_marks(ctx);
    release_all(ctx);
    throw;
  }
  out.stamp = verts[v].stamp.load(std::memory_order_relaxed);
  cone_from_vertex(ctx, v);
  grid_note(ctx, v);
  // A start for contexts that know no vertex yet; refreshed rarely (shared line).
  if ((ctx.insertions_made & 63) == 1) recent_vertex.store(v, std::memory_order_relaxed);
  ++ctx.stats.insertions;
  finish_change(ctx, OpKind::insert, v, out.stamp);
  out.result = {v, true, out.stamp};
  return OpStatus::done;
}

OpStatus Triangulation::Impl::gather_conflict_zone(OpContext& ctx, const KPoint& p, CellId c0,
                                                   const detail::FilterEps& eps) {
  // Bowyer-Watson: the cells whose (perturbed) circumsphere contains p form a
  // connected, star-shaped conflict zone; search it breadth first. c0 is held
  // exclusively; each cell joining the zone is locked exclusively before its
  // own neighbours are read. Marks: in for the zone, out for a cell found
  // outside it; every mark set here is cleared before returning, but for the
  // zone's when the search is done: the cone renews or frees every zone
  // cell, which clears its mark, and a caller that does not get that far
  // clears them (clear_zone_marks).
  std::vector<CellId>& zone = ctx.conflict_zone;
  zone.clear();
  ctx.boundary.clear();
  auto unmark_outside = [&] {
    for (const OpContext::BoundaryFacet& bf : ctx.boundary) set_mark(bf.outer >> 2, 0);
  };
  auto unmark = [&] {
    clear_zone_marks(ctx);
    unmark_outside();
  };
  auto fetch_neighbours = [&](CellId c) {  // their records and tags, for when c is searched
    for (int j = 0; j < 4; ++j) {
      __builtin_prefetch(&cells[cells[c].n[j] >> 2]);
      __builtin_prefetch(&tags[cells[c].n[j] >> 2]);
    }
  };
  OpStatus status = OpStatus::done;
  try {
    set_mark(c0, mark_in);
    zone.push_back(c0);
    fetch_neighbours(c0);
    for (std::size_t idx = 0; idx < zone.size() && status == OpStatus::done; ++idx) {
      CellId c = zone[idx];
      // Cells are scattered in memory: fetch ahead. The neighbours' records
      // were fetched when c joined the zone; now the one point each adds.
      for (int i = 0; i < 4; ++i) {
        const std::uint32_t nw = cells[c].n[i];
        __builtin_prefetch(&pt(cells[nw >> 2].v[nw & 3]));
      }
      // The unmarked neighbours' verdicts first, then what they say: four
      // tests in flight at once rather than each after the last one's
      // (unpredictable) branch. Not in a removal's small triangulation,
      // whose cells are mostly infinite (there it cost removals 4%).
      int verdict[4] = {0, 0, 0, 0};
      if (!is_small)
        for (int i = 0; i < 4; ++i) {
          const CellId nb = cells[c].n[i] >> 2;
          verdict[i] = mark(nb) == 0 ? quick_conflict(nb, p, eps) : 0;
        }
      for (int i = 0; i < 4; ++i) {
        std::uint32_t nw = cells[c].n[i];
        CellId nb = nw >> 2;
        const std::uint32_t m = mark(nb);
        if (m == mark_in) continue;
        if (m != mark_out) {
          if (verdict[i] > 0 || (verdict[i] == 0 && in_conflict(nb, p, eps))) {
            if (!lock_exclusive(ctx, cells[nb].v[nw & 3])) {
              status = OpStatus::rollback;
              break;
            }
            PDT_FAULT_POINT("conflict zone");
            zone.push_back(nb);
            set_mark(nb, mark_in);
            fetch_neighbours(nb);
            continue;
          }
        }
        OpContext::BoundaryFacet bf;
        std::memcpy(bf.v, cells[c].v, sizeof bf.v);
        bf.outer = nw;
        bf.facet = i;
        PDT_FAULT_POINT("conflict zone");
        ctx.boundary.push_back(bf);
        set_mark(nb, mark_out);
      }
    }
  } catch (...) {
    unmark();
    throw;
  }
  if (status == OpStatus::done)
    unmark_outside();
  else
    unmark();
  return status;
}

namespace {

// The cone's cell over the boundary facet that was facet f of a zone cell x
// is (v, x[t[0]], x[t[1]], x[t[2]]) with t = cone_order[f]: v first, then
// the facet's vertices in facet_vertex[f]'s cyclic order reversed, which
// keeps the orientation of x with v in place of x[f] (the positions
// (f, t[0], t[1], t[2]) are an even permutation of (0, 1, 2, 3): asserted
// below). So every cone cell has v at 0, its boundary facet is its facet 0
// and lists the facet's vertices in x's cyclic order, and its facets through
// v are fixed: cone_edges[k - 1] says that facet k (1..3) holds v and the
// directed edge (x, y) that follows v in facet_vertex[k]'s cyclic order.
constexpr auto cone_order = [] {
  std::array<std::array<int, 3>, 4> out{};
  for (int f = 0; f < 4; ++f) {
    const int* fv = detail::facet_vertex[f];
    out[f] = {fv[0], fv[2], fv[1]};
  }
  return out;
}();
struct ConeEdge {
  int k, x, y;
};
constexpr auto cone_edges = [] {
  std::array<ConeEdge, 3> out{};
  for (int k = 1; k < 4; ++k) {
    const int* fv = detail::facet_vertex[k];
    const int j = fv[0] == 0 ? 0 : fv[1] == 0 ? 1 : 2;
    out[k - 1] = {k, fv[(j + 1) % 3], fv[(j + 2) % 3]};
  }
  return out;
}();
// Checked at compile time: each cone cell lists its vertices as an even
// permutation of the zone cell's (with v in place of x[f]).
constexpr bool cone_order_is_even() {
  for (int f = 0; f < 4; ++f) {
    const int perm[4] = {f, cone_order[f][0], cone_order[f][1], cone_order[f][2]};
    int inversions = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) inversions += perm[a] > perm[b];
    if (inversions % 2 != 0) return false;
  }
  return true;
}
static_assert(cone_order_is_even());
static_assert(cone_edges[0].x == 2 && cone_edges[0].y == 3 && cone_edges[1].x == 3 && cone_edges[1].y == 1 &&
              cone_edges[2].x == 1 && cone_edges[2].y == 2);

}  // namespace

void Triangulation::Impl::cone_from_vertex(OpContext& ctx, VertexId v) {
  // Replace the conflict zone by the cone from v over its boundary. The
  // zone's ids go straight to the cone's first cells, each renewed (a new
  // incarnation), rather than through the pool's free list; the pool makes
  // the rest (a cone nearly always has more cells than its zone, so the pool
  // seldom takes a zone id back). Nothing here allocates: the caller
  // reserved the cells and the edge map.
  std::vector<CellId>& zone = ctx.conflict_zone;
  const std::size_t facets = ctx.boundary.size();
  std::size_t kept = 0;  // zone[0, kept): the ids the cone takes over
  for (const CellId c : zone) {
    if (!cell_infinite(c)) --ctx.d_finite_cells;
    note_destroyed(ctx, c);
    if (kept < facets && !retires(c))
      zone[kept++] = c;
    else
      free_cell(ctx, c);  // a retired id, or one the cone has no cell for
  }
  for (std::size_t k = 0; k < facets; ++k) {
    OpContext::BoundaryFacet& bf = ctx.boundary[k];
    CellId nc;
    if (k < kept) {
      nc = zone[k];
      renew(nc);
    } else {
      nc = alloc_cell(ctx);
    }
    note_created(ctx, nc);
    // bf.v becomes the cone cell's vertices (cone_order), for link_cone too.
    // Built aside and copied whole to both: storing into bf.v and then
    // copying it would make each 16-byte load wait on four 4-byte stores it
    // cannot be forwarded from (compilers differ on whether they avoid it).
    const std::array<int, 3>& t = cone_order[bf.facet];
    const VertexId made[4] = {v, bf.v[t[0]], bf.v[t[1]], bf.v[t[2]]};
    CellRec& r = cells[nc];
    std::memcpy(r.v, made, sizeof r.v);
    std::memcpy(bf.v, made, sizeof bf.v);
    set_adjacency(nc, 0, bf.outer >> 2, static_cast<int>(bf.outer & 3));
    bool finite = true;
    for (int i = 1; i < 4; ++i) {  // the facet's vertices; v's own below
      const VertexId w = bf.v[i];
      if (w == 0) {
        finite = false;
        continue;
      }
      verts[w].cell = nc;
      verts[w].scratch = 0;  // unnumbered (link_cone)
    }
    if (finite) ++ctx.d_finite_cells;
    bf.outer = nc;  // from here on: the new cell
  }
  verts[v].cell = ctx.boundary.back().outer;
  link_cone(ctx);
  ctx.stats.cells_created_by_insert += facets;
}

void Triangulation::Impl::link_cone(OpContext& ctx) {
  // The new cells' facets through v pair up: facet k (1..3) of new cell c
  // holds v and one boundary edge, seen from c as the directed edge (x, y)
  // that follows v in the facet's cyclic order (cone_edges); the cell across
  // sees (y, x) (storage.hpp: a shared facet is listed in opposite cyclic
  // orders). Every directed edge of the closed boundary surface occurs
  // exactly once, so a table indexed by directed edge needs no clearing: all
  // writes, then all reads. The boundary's vertices are numbered in their
  // scratch words (zeroed by cone_from_vertex), which this operation owns: it
  // holds them exclusively. The infinite vertex, which nobody locks, keeps
  // number 0 and its scratch is never written; v is in no boundary edge and
  // gets no number.
  std::vector<OpContext::BoundaryFacet>& bnd = ctx.boundary;
  constexpr std::uint32_t ids = OpContext::cone_ids;
  std::uint32_t next = 1;
  for (const OpContext::BoundaryFacet& bf : bnd)
    for (int t = 1; t < 4; ++t) {
      const VertexId w = bf.v[t];
      if (w == 0) continue;
      std::uint32_t& s = verts[w].scratch;
      const std::uint32_t unnumbered = s == 0;
      s |= unnumbered * next;
      next += unnumbered;
    }
  if (next <= ids) {
    // Rows of `next` entries, not `ids`: the table's used part is dense
    // (next^2 entries, about 1 KB for a typical cone of 16 vertices).
    std::uint32_t* table = ctx.cone_edge.data();
    const std::uint32_t stride = next;
    for (OpContext::BoundaryFacet& bf : bnd)
      for (int t = 1; t < 4; ++t) bf.v[t] = verts[bf.v[t]].scratch;  // bf.v[1..3] now hold numbers
    for (const OpContext::BoundaryFacet& bf : bnd)
      for (const ConeEdge& ce : cone_edges)
        table[stride * bf.v[ce.x] + bf.v[ce.y]] = 4 * bf.outer + static_cast<std::uint32_t>(ce.k);
    for (const OpContext::BoundaryFacet& bf : bnd)
      for (const ConeEdge& ce : cone_edges) {
        const std::uint32_t across = table[stride * bf.v[ce.y] + bf.v[ce.x]];
        assert(cells[across >> 2].v[across & 3] != cells[bf.outer].v[ce.x] &&
               cells[across >> 2].v[across & 3] != cells[bf.outer].v[ce.y]);
        cells[bf.outer].n[ce.k] = across;
      }
    return;
  }
  detail::IdMap& edges = ctx.new_cell_by_edge;  // reserved by the caller for 3 entries per facet
  edges.clear();
  for (const OpContext::BoundaryFacet& bf : bnd)
    for (const ConeEdge& ce : cone_edges) {
      bool inserted = false;
      const std::uint32_t val = edges.get_or_insert(edge_key(bf.v[ce.x], bf.v[ce.y]),
                                                    4 * bf.outer + static_cast<std::uint32_t>(ce.k), &inserted);
      if (!inserted) set_adjacency(bf.outer, ce.k, val >> 2, static_cast<int>(val & 3));
    }
}

}  // namespace pdt
