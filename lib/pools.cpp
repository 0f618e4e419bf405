// SPDX-License-Identifier: MIT
// Storage and per-thread pools (paper §3.2): each context allocates cell and
// vertex ids from its own free lists, refilled by chunks carved from the
// shared StableArrays; its count changes are folded into the totals later.
#include "fault_injection.hpp"
#include "mix64.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::mix64;
using detail::no_index;
using detail::OpContext;

namespace {

// Address space reserved for the storage (pages are committed on first touch).
constexpr std::size_t max_cells = std::size_t{1} << 31;
constexpr std::size_t max_vertices = std::size_t{1} << 29;
constexpr std::size_t max_small_cells = std::size_t{1} << 24;
constexpr std::size_t max_small_vertices = std::size_t{1} << 22;

// Pool chunks (paper §3.2): 12 pages of cells, 3 pages of vertices.
constexpr std::uint32_t cell_chunk = 12 * 4096 / sizeof(detail::CellRec);
constexpr std::uint32_t vertex_chunk = 3 * 4096 / sizeof(detail::VertexRec);

}  // namespace

namespace detail {

OpContext::OpContext(std::uint32_t id_, bool locking_)
    : id(id_), locking(locking_), rng(0x9E3779B97F4A7C15ull ^ mix64(id_)) {
  new_cell_by_edge.reserve_for(64);
  cone_edge.resize(std::size_t{cone_ids} * cone_ids);
  link.reserve(64);
  held_shared.reserve(64);
  held_exclusive.reserve(64);
}
OpContext::~OpContext() = default;

}  // namespace detail

Triangulation::Impl::Impl(bool small_triangulation)
    : cells(small_triangulation ? max_small_cells : max_cells, !small_triangulation),
      tags(small_triangulation ? max_small_cells : max_cells, !small_triangulation),
      verts(small_triangulation ? max_small_vertices : max_vertices, !small_triangulation),
      is_small(small_triangulation),
      seq(std::make_unique<OpContext>(1, false)) {
  verts.grow(1);  // vertex 0: the infinite vertex
  verts[0].multiplicity = 1;
}

Triangulation::Impl::~Impl() = default;

std::uint32_t Triangulation::Impl::new_context_id() {
  const std::uint32_t id = next_context_id.fetch_add(1, std::memory_order_relaxed);
  // Lock words hold -(owner) in an int32: ids must stay below 2^31. Ids are
  // handed out once per context ever made (an engine makes one per worker).
  if (id >= (std::uint32_t{1} << 31)) throw std::bad_alloc();
  return id;
}

std::uint64_t Triangulation::Impl::new_incarnation(OpContext& ctx) {
  if (ctx.incarnation_next == ctx.incarnation_end) {
    constexpr std::uint64_t block = std::uint64_t{1} << 16;
    // 1-based: 0 means "no incarnation" (a free vertex).
    ctx.incarnation_next = next_incarnation_block.fetch_add(block, std::memory_order_relaxed) + 1;
    ctx.incarnation_end = ctx.incarnation_next + block;
  }
  return ctx.incarnation_next++;
}

void Triangulation::Impl::reserve_cells(OpContext& ctx, std::size_t n) {
  std::size_t have = ctx.free_cells.count + (ctx.fresh_cell_end - ctx.fresh_cell);
  while (have < n) {
    // A new chunk; the ids left in the current one go to the free list first.
    PDT_FAULT_POINT("cell chunk");
    const std::size_t first = cells.grow(cell_chunk);
    tags.ensure_size(first + cell_chunk);
    bool any_retired = false;  // ids past clear() keep their incarnations
    for (std::size_t i = first; i < first + cell_chunk; ++i) {
      cells[i].v[0] = no_vertex;  // not live yet
      any_retired |= incarnation(static_cast<CellId>(i)) == last_incarnation;
    }
    while (ctx.fresh_cell != ctx.fresh_cell_end) {
      const CellId c = ctx.fresh_cell++;
      ++ctx.d_cells;  // free_cell counts a release
      free_cell(ctx, c);
    }
    ctx.fresh_cell = static_cast<std::uint32_t>(first);
    ctx.fresh_cell_end = static_cast<std::uint32_t>(first + cell_chunk);
    if (any_retired)  // rare: through the free list, which leaves the retired ids out
      while (ctx.fresh_cell != ctx.fresh_cell_end) {
        ++ctx.d_cells;
        free_cell(ctx, ctx.fresh_cell++);
      }
    have = ctx.free_cells.count + (ctx.fresh_cell_end - ctx.fresh_cell);
  }
}

CellId Triangulation::Impl::alloc_cell(OpContext& ctx) {
  CellId c;
  if (ctx.free_cells.head != no_index) {
    c = ctx.free_cells.head;
    ctx.free_cells.head = cells[c].n[0];
    if (--ctx.free_cells.count == 0) ctx.free_cells.tail = no_index;
  } else {
    if (ctx.fresh_cell == ctx.fresh_cell_end) reserve_cells(ctx, 1);
    c = ctx.fresh_cell++;
  }
  renew(c);
  ++ctx.d_cells;
  return c;
}

void Triangulation::Impl::free_all_cells(OpContext& ctx) {
  for (CellId c = 0; c < cells.size(); ++c) {
    if (!cell_alive(c)) continue;
    if (!cell_infinite(c)) --ctx.d_finite_cells;
    note_destroyed(ctx, c);
    free_cell(ctx, c);
  }
}

void Triangulation::Impl::free_cell(OpContext& ctx, CellId c) {
  cells[c].v[0] = no_vertex;
  if (incarnation(c) == last_incarnation) {  // retired: a next incarnation would wrap
    --ctx.d_cells;
    return;
  }
  cells[c].n[0] = ctx.free_cells.head;
  if (ctx.free_cells.count++ == 0) ctx.free_cells.tail = c;
  ctx.free_cells.head = c;
  --ctx.d_cells;
}

VertexId Triangulation::Impl::alloc_vertex(OpContext& ctx, const KPoint& p) {
  // Any free id may be held shared by a reader that found it (a stale
  // jump-grid slot, a random probe) and is checking whether it is alive. We
  // write a vertex only once we hold it, so an id we cannot lock is skipped
  // (a fresh one goes to our free list for later).
  VertexId v = no_vertex;
  if (ctx.free_vertices.head != no_index && lock_exclusive(ctx, ctx.free_vertices.head)) {
    v = ctx.free_vertices.head;
    ctx.free_vertices.head = verts[v].cell;
    if (--ctx.free_vertices.count == 0) ctx.free_vertices.tail = no_index;
  }
  while (v == no_vertex) {
    if (ctx.fresh_vertex == ctx.fresh_vertex_end) {
      // Fresh records are all-zero (a free vertex) without construction; see
      // StableArray::grow. The small triangulation reuses its memory, and is
      // single-threaded, so it constructs.
      PDT_FAULT_POINT("vertex chunk");
      std::size_t first = verts.grow(vertex_chunk, is_small);
      ctx.fresh_vertex = static_cast<std::uint32_t>(first);
      ctx.fresh_vertex_end = static_cast<std::uint32_t>(first + vertex_chunk);
    }
    VertexId f = ctx.fresh_vertex++;
    if (lock_exclusive(ctx, f)) {
      v = f;
    } else {
      verts[f].cell = ctx.free_vertices.head;  // the prober only reads multiplicity (0)
      if (ctx.free_vertices.count++ == 0) ctx.free_vertices.tail = f;
      ctx.free_vertices.head = f;
    }
  }
  VertexRec& r = verts[v];
  {
    VertexWrite hold(*this, ctx, v);
    r.p = p;
    r.cell = no_cell;
    r.multiplicity = 1;
    r.stamp.store(new_incarnation(ctx), std::memory_order_release);
  }
  ++ctx.insertions_made;
  ++ctx.d_vertices;
  ctx.last_vertex = v;
  return v;
}

void Triangulation::Impl::free_vertex(OpContext& ctx, VertexId v) {
  VertexRec& r = verts[v];
  {
    VertexWrite hold(*this, ctx, v);
    r.multiplicity = 0;
    r.stamp.store(0, std::memory_order_relaxed);
  }
  r.cell = ctx.free_vertices.head;
  if (ctx.free_vertices.count++ == 0) ctx.free_vertices.tail = v;
  ctx.free_vertices.head = v;
  --ctx.d_vertices;
  if (ctx.last_vertex == v) ctx.last_vertex = no_vertex;
}

void Triangulation::Impl::merge_pools(OpContext& into, OpContext& from) {
  while (from.fresh_cell != from.fresh_cell_end) {
    CellId c = from.fresh_cell++;
    ++from.d_cells;  // free_cell counts a release
    free_cell(from, c);
  }
  while (from.fresh_vertex != from.fresh_vertex_end) {
    VertexId v = from.fresh_vertex++;
    ++from.d_vertices;
    free_vertex(from, v);
  }
  auto splice = [](detail::FreeList& a, detail::FreeList& b, auto next_of) {
    if (b.count == 0) return;
    next_of(b.tail) = a.head;
    if (a.count == 0) a.tail = b.tail;
    a.head = b.head;
    a.count += b.count;
    b = detail::FreeList{};
  };
  splice(into.free_cells, from.free_cells, [&](std::uint32_t c) -> std::uint32_t& { return cells[c].n[0]; });
  splice(into.free_vertices, from.free_vertices, [&](std::uint32_t v) -> std::uint32_t& { return verts[v].cell; });
  fold_counters(from);
}

void Triangulation::Impl::end_op_counters(OpContext& ctx) {
  // An engine worker folds its deltas only when it goes idle or to sleep (see
  // the engine's workers) or when they grow large: three shared counters
  // updated after every operation would be one cache line bouncing between
  // all workers.
  constexpr std::int64_t kFoldAt = 4096;
  if (!ctx.locking || ctx.d_cells >= kFoldAt || ctx.d_cells <= -kFoldAt) fold_counters(ctx);
}

void Triangulation::Impl::fold_counters(OpContext& ctx) {
  if (ctx.d_vertices) n_vertices.fetch_add(ctx.d_vertices, std::memory_order_relaxed);
  if (ctx.d_cells) n_cells.fetch_add(ctx.d_cells, std::memory_order_relaxed);
  if (ctx.d_finite_cells) n_finite_cells.fetch_add(ctx.d_finite_cells, std::memory_order_relaxed);
  ctx.d_vertices = ctx.d_cells = ctx.d_finite_cells = 0;
}

void Triangulation::Impl::clear() {
  // A small (per-removal) triangulation keeps its pages: it is cleared per
  // operation. The tags keep their contents: cell incarnations go on counting.
  cells.clear(!is_small);
  tags.clear(false);
  verts.clear(!is_small);
  verts.grow(1);
  verts[0].multiplicity = 1;
  dim = -1;
  n_vertices = n_cells = n_finite_cells = 0;
  flat.clear();
  flat_index.clear();
  basis.clear();
  grid = detail::JumpGrid{};
  recent_vertex.store(no_vertex);
  OpContext& c = *seq;
  c.free_cells = c.free_vertices = detail::FreeList{};
  c.fresh_cell = c.fresh_cell_end = c.fresh_vertex = c.fresh_vertex_end = 0;
  c.d_vertices = c.d_cells = c.d_finite_cells = 0;
  c.last_vertex = no_vertex;
}

}  // namespace pdt
