// SPDX-License-Identifier: MIT
// Storage and per-thread pools (paper §3.2): each context allocates cell and
// vertex ids from its own free lists, refilled by chunks carved from the
// shared StableArrays; its count changes are folded into the totals later.
#include <algorithm>
#include <cassert>
#include <iterator>
#include <mutex>

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

// Pool chunks (paper §3.2): 12 pages of cells, 3 pages of vertices. A
// removal's small triangulation, cleared for every removal and carving its
// storage again each time (a link of some 30 vertices, a few hundred cells),
// carves 2 pages of cells and 1 of vertices: a whole chunk's records, reset
// for each removal, were 60 KB of writes for a link that needs a few.
constexpr std::uint32_t cell_chunk = 12 * 4096 / sizeof(detail::CellRec);
constexpr std::uint32_t vertex_chunk = 3 * 4096 / sizeof(detail::VertexRec);
constexpr std::uint32_t small_cell_chunk = 2 * 4096 / sizeof(detail::CellRec);
constexpr std::uint32_t small_vertex_chunk = 4096 / sizeof(detail::VertexRec);

// Free-list segments (storage.hpp): a context keeps fewer than 2S free ids
// of a kind and trades the rest in segments of S with the spare stack.
constexpr std::uint32_t cell_segment = cell_chunk;
constexpr std::uint32_t vertex_segment = vertex_chunk;

template <std::uint32_t S, class Next>
void push_id(detail::FreeList& l, std::uint32_t id, Next next) {
  next(id) = l.head;
  l.head = id;
  ++l.count;
  if (l.count == S)
    l.mark = id;
  else if (l.count == S + 1)
    l.boundary = id;
}

template <std::uint32_t S, class Next>
std::uint32_t pop_id(detail::FreeList& l, Next next) {
  const std::uint32_t id = l.head;
  l.head = next(id);
  if (l.count == S)
    l.mark = no_index;  // id was the mark
  else if (l.count == S + 1)
    l.boundary = no_index;  // id was the boundary
  --l.count;
  return id;
}

#ifndef NDEBUG
template <std::uint32_t S, class Next>
bool list_ok(const detail::FreeList& l, Next next) {
  std::size_t n = 0, from_mark = 0;
  bool past_mark = false;
  std::uint32_t before = no_index;
  for (std::uint32_t id = l.head; id != no_index; id = next(id)) {
    if (id == l.mark) {
      past_mark = true;
      if (l.boundary != before) return false;
    }
    ++n;
    from_mark += past_mark;
    before = id;
  }
  return n == l.count && l.count < 2 * S && (l.count >= S ? past_mark && from_mark == S : l.mark == no_index) &&
         (l.count >= S + 1 || l.boundary == no_index);
}
#endif

}  // namespace

// A push that keeps count < 2S: at 2S the oldest S ids go to the spare stack.
template <std::uint32_t S, class Next, class Link>
void Triangulation::Impl::give_id(detail::FreeList& l, std::uint32_t id, detail::SpareSegments& spare, Next next,
                                  Link link) {
  push_id<S>(l, id, next);
  if (l.count < 2 * S) return;
  const std::uint32_t first = l.mark;
  next(l.boundary) = no_index;
  l.count = S;
  l.mark = l.head;
  l.boundary = no_index;
  assert(list_ok<S>(l, next));
  std::lock_guard lock(spare_mutex);
  link(first) = spare.head.load(std::memory_order_relaxed);
  spare.head.store(first, std::memory_order_relaxed);
}

// Takes a spare segment below l (l.count < S, so l stays under 2S). False if
// there is none.
template <std::uint32_t S, class Next, class Link>
bool Triangulation::Impl::take_spare(detail::FreeList& l, detail::SpareSegments& spare, Next next, Link link) {
  assert(l.count < S);
  if (spare.head.load(std::memory_order_relaxed) == no_index) return false;  // nothing (or a race: next time)
  std::uint32_t first;
  {
    std::lock_guard lock(spare_mutex);
    first = spare.head.load(std::memory_order_relaxed);
    if (first == no_index) return false;
    spare.head.store(link(first), std::memory_order_relaxed);
  }
  std::uint32_t last = no_index;
  for (std::uint32_t id = l.head; id != no_index; id = next(id)) last = id;
  if (last == no_index)
    l.head = first;
  else
    next(last) = first;
  l.count += S;
  l.mark = first;
  l.boundary = last;
  assert(list_ok<S>(l, next));
  return true;
}

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

namespace {
std::uint32_t new_mesh_id() {
  static std::atomic<std::uint32_t> next{1};
  std::uint32_t id = next.fetch_add(1, std::memory_order_relaxed);
  while (id == 0) id = next.fetch_add(1, std::memory_order_relaxed);  // wrapped: 0 is no mesh
  return id;
}
}  // namespace

Triangulation::Impl::Impl(bool small_triangulation)
    : mesh_id(new_mesh_id()),
      cells(small_triangulation ? max_small_cells : max_cells, !small_triangulation),
      tags(small_triangulation ? max_small_cells : max_cells, !small_triangulation),
      verts(small_triangulation ? max_small_vertices : max_vertices, !small_triangulation),
      is_small(small_triangulation),
      seq(std::make_unique<OpContext>(1, false)) {
  verts.grow(1);  // vertex 0: the infinite vertex
  verts[0].multiplicity = 1;
}

Triangulation::Impl::~Impl() = default;

void detail::OpContext::release_large_scratch() {
  auto release = [](auto& v) {
    if (v.capacity() > scratch_kept) std::remove_reference_t<decltype(v)>().swap(v);
  };
  release(conflict_zone);
  release(boundary);
  release(cone_edge);
  release(hole);
  release(link);
  release(small_facet_boundary);
  release(small_inside);
  release(small_to_new);
  release(small_star);
  release(small_seen);  // regrown with zeros: no generation matches them
  release(created);
  release(destroyed);
  release(views);
  for (IdMap* m : {&new_cell_by_edge, &hole_facet_by_triple, &star_seen})
    if (m->slots() > 2 * scratch_kept) m->release();
  if (small && small->cells.size() > scratch_kept) small.reset();  // made again by the next removal
}

std::uint32_t Triangulation::Impl::new_context_id() {
  const std::uint32_t id = next_context_id.fetch_add(1, std::memory_order_relaxed);
  // Lock words hold -(owner) in an int32: ids must stay below 2^31. Ids are
  // handed out once per context ever made (an engine makes one per worker).
  if (id >= (std::uint32_t{1} << 31)) throw std::bad_alloc();
  return id;
}

namespace {
// Vertex incarnations for every triangulation of the process: a VertexHandle
// from one triangulation (or from the one a moved-over object held before)
// never names a vertex of another. 2^48 blocks: no wrap in practice.
std::atomic<std::uint64_t> next_incarnation_block{0};
}  // namespace

std::uint64_t Triangulation::Impl::new_incarnation(OpContext& ctx) {
  if (ctx.incarnation_next == ctx.incarnation_end) {
    constexpr std::uint64_t block = std::uint64_t{1} << 16;
    // 1-based: 0 means "no incarnation" (a free vertex).
    ctx.incarnation_next = next_incarnation_block.fetch_add(block, std::memory_order_relaxed) + 1;
    ctx.incarnation_end = ctx.incarnation_next + block;
  }
  return ctx.incarnation_next++;
}

bool Triangulation::Impl::reserve_spare_segment(OpContext& ctx) {
  if (spare_cells.head.load(std::memory_order_relaxed) == no_index) return false;  // nothing (or a race: next time)
  std::uint32_t first;
  {
    std::lock_guard lock(spare_mutex);
    first = spare_cells.head.load(std::memory_order_relaxed);
    if (first == no_index) return false;
    spare_cells.head.store(cell_link()(first), std::memory_order_relaxed);
  }
  cell_link()(first) = ctx.reserved_more;
  ctx.reserved_more = first;
  ctx.reserved_cells += cell_segment;
  return true;
}

CellId Triangulation::Impl::pop_reserved_cell(OpContext& ctx) {
  assert(ctx.reserved_cells > 0);
  if (ctx.reserved_head == no_index) {  // the next segment: its stack link is read before its ids go
    const std::uint32_t first = ctx.reserved_more;
    ctx.reserved_more = cell_link()(first);
    ctx.reserved_head = first;
  }
  const CellId c = ctx.reserved_head;
  ctx.reserved_head = cell_next()(c);
  --ctx.reserved_cells;
  assert((ctx.reserved_cells == 0) == (ctx.reserved_head == no_index && ctx.reserved_more == no_index));
  return c;
}

void Triangulation::Impl::reserve_cells(OpContext& ctx, std::size_t n) {
  // What the next allocations can count on: frees meanwhile may give the
  // oldest S of the list away, but never leave it under S, so the list
  // counts for at most S; the reserved segments and the fresh range count whole.
  auto have = [&] {
    return std::min<std::size_t>(ctx.free_cells.count, cell_segment) + ctx.reserved_cells +
           (ctx.fresh_cell_end - ctx.fresh_cell);
  };
  if (have() >= n) return;
  if (ctx.free_cells.count < cell_segment &&
      take_spare<cell_segment>(ctx.free_cells, spare_cells, cell_next(), cell_link()) && have() >= n)
    return;
  // A cavity larger than a list keeps: the spare segments first. Without
  // them, every such cavity took a fresh range while the ids the last one
  // freed sat in the spare stack (a vertex at the centre of 20k cospherical
  // points inserted and removed 40 times: 7.5 KB a vertex for the mesh).
  while (have() < n && reserve_spare_segment(ctx)) {
  }
  if (have() >= n) return;
  // A new range of fresh ids, enough with what the list and the reserved
  // segments hold (a large cavity can need more than a list ever keeps); the
  // ids left in the current range go to the free list, which then counts for
  // no less than now.
  const std::size_t chunk = is_small ? small_cell_chunk : cell_chunk;
  const std::size_t held = std::min<std::size_t>(ctx.free_cells.count, cell_segment) + ctx.reserved_cells;
  const std::size_t short_by = n > held ? n - held : 1;
  const std::size_t size = std::max<std::size_t>(1, (short_by + chunk - 1) / chunk) * chunk;
  std::size_t first;
  for (;;) {
    PDT_FAULT_POINT("cell chunk");
    // Committed before the records are first written: constructing them
    // first would take a fault per page, and populate would find nothing left.
    first = cells.grow(size, false);
    tags.ensure_size(first + size);
    cells.populate(first, first + size);
    tags.populate(first, first + size);  // renew() reads a tag before writing it
    // Ids whose tags were given back read 0 here: they start at the floor.
    for (std::size_t i = first; i < std::min(first + size, tag_floor_end); ++i)
      if (incarnation(static_cast<CellId>(i)) < tag_floor) tags[i].store(tag_floor << 2 | mark_free, std::memory_order_relaxed);
    for (std::size_t i = first; i < first + size; ++i) {
      new (&cells[i]) CellRec();
      cells[i].v[0] = no_vertex;  // not live yet
    }
    // Ids past clear() keep their incarnations: one may be at the last.
    bool any_retired = false;
    if (some_id_retiring.load(std::memory_order_relaxed))
      for (std::size_t i = first; i < first + size; ++i)
        any_retired |= incarnation(static_cast<CellId>(i)) >= retire_at;
    if (!any_retired) break;
    // Rare (an id allocated 2^30 times, then clear()): that range stays unused.
  }
  while (ctx.fresh_cell != ctx.fresh_cell_end) {
    const CellId c = ctx.fresh_cell++;
    ++ctx.d_cells;  // free_cell counts a release
    free_cell(ctx, c);
  }
  ctx.fresh_cell = static_cast<std::uint32_t>(first);
  ctx.fresh_cell_end = static_cast<std::uint32_t>(first + size);
  assert(have() >= n);
}

CellId Triangulation::Impl::alloc_cell(OpContext& ctx) {
  if (ctx.free_cells.count == 0 && ctx.reserved_cells == 0 && ctx.fresh_cell == ctx.fresh_cell_end)
    reserve_cells(ctx, 1);
  const CellId c = ctx.free_cells.count ? pop_id<cell_segment>(ctx.free_cells, cell_next())
                   : ctx.reserved_cells ? pop_reserved_cell(ctx)
                                        : ctx.fresh_cell++;
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
  // Every slot: a free record names no vertex, so a handle check holding a
  // vertex of the cell it was never finds that vertex here (hold_cell).
  for (VertexId& w : cells[c].v) w = no_vertex;
  set_mark(c, mark_free);  // I8: handles to it read as dead from here on
  --ctx.d_cells;
  if (retires(c)) return;
  give_id<cell_segment>(ctx.free_cells, c, spare_cells, cell_next(), cell_link());
}

VertexId Triangulation::Impl::alloc_vertex(OpContext& ctx, const KPoint& p) {
  // Any free id may be held shared by a reader that found it (a stale
  // jump-grid slot, a random probe) and is checking whether it is alive. We
  // write a vertex only once we hold it, so an id we cannot lock is skipped
  // (a fresh one goes to our free list for later).
  // The first few ids of the list are tried: one held is set aside and put
  // back after. Under an engine the ids freed last are the ones stale grid
  // slots still name, so the head is the id most often held; giving up at a
  // held head took a fresh id while the list kept its own, and the id range
  // crept up (3,000 live vertices, 300 inserted and undone per round on 2
  // workers: 3,585 ids after 10 rounds, 6,657 after 10,000).
  VertexId v = no_vertex;
  VertexId set_aside[3];
  unsigned aside = 0;
  while (ctx.free_vertices.count) {
    if (lock_exclusive(ctx, ctx.free_vertices.head)) {
      v = pop_id<vertex_segment>(ctx.free_vertices, vertex_next());
      break;
    }
    if (aside == std::size(set_aside)) break;
    set_aside[aside++] = pop_id<vertex_segment>(ctx.free_vertices, vertex_next());
  }
  while (aside) give_id<vertex_segment>(ctx.free_vertices, set_aside[--aside], spare_vertices, vertex_next(), vertex_link());
  while (v == no_vertex) {
    if (ctx.fresh_vertex == ctx.fresh_vertex_end) {
      if (ctx.free_vertices.count < vertex_segment &&
          take_spare<vertex_segment>(ctx.free_vertices, spare_vertices, vertex_next(), vertex_link()) &&
          lock_exclusive(ctx, ctx.free_vertices.head)) {
        v = pop_id<vertex_segment>(ctx.free_vertices, vertex_next());
        break;
      }
      if (take_released_vertices(ctx)) continue;
      // Fresh records are all-zero (a free vertex) without construction; see
      // StableArray::grow. The small triangulation reuses its memory, and is
      // single-threaded, so it constructs.
      PDT_FAULT_POINT("vertex chunk");
      const std::size_t chunk = is_small ? small_vertex_chunk : vertex_chunk;
      std::size_t first = verts.grow(chunk, is_small);
      verts.populate(first, first + chunk);
      ctx.fresh_vertex = static_cast<std::uint32_t>(first);
      ctx.fresh_vertex_end = static_cast<std::uint32_t>(first + chunk);
    }
    VertexId f = ctx.fresh_vertex++;
    if (lock_exclusive(ctx, f)) {
      v = f;
    } else {  // the prober only reads multiplicity (0)
      give_id<vertex_segment>(ctx.free_vertices, f, spare_vertices, vertex_next(), vertex_link());
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

std::vector<detail::IdRange> Triangulation::Impl::released_ranges() const {
  std::vector<detail::IdRange> out;
  if (released_vertex_count.load(std::memory_order_relaxed) == 0) return out;
  {
    std::lock_guard lock(spare_mutex);
    out.reserve(released_vertices.size());
    for (const IdRun& run : released_vertices)
      if (run.count != 0) out.push_back({run.first, run.first + run.count});
  }
  std::sort(out.begin(), out.end(), [](detail::IdRange a, detail::IdRange b) { return a.first < b.first; });
  return out;
}

bool Triangulation::Impl::take_released_vertices(OpContext& ctx) {
  if (released_vertex_count.load(std::memory_order_relaxed) == 0) return false;
  std::uint32_t first, count;
  {
    std::lock_guard lock(spare_mutex);
    if (released_vertices.empty()) return false;
    IdRun& run = released_vertices.back();  // the lowest run (shrink_to_fit)
    count = std::min(run.count, vertex_chunk);
    first = run.first;
    run.first += count;
    run.count -= count;
    if (run.count == 0) released_vertices.pop_back();
    released_vertex_count.fetch_sub(count, std::memory_order_relaxed);
  }
  verts.populate(first, first + count);
  ctx.fresh_vertex = first;
  ctx.fresh_vertex_end = first + count;
  return true;
}

void Triangulation::Impl::free_vertex(OpContext& ctx, VertexId v) {
  VertexRec& r = verts[v];
  {
    VertexWrite hold(*this, ctx, v);
    r.multiplicity = 0;
    r.stamp.store(0, std::memory_order_relaxed);
  }
  give_id<vertex_segment>(ctx.free_vertices, v, spare_vertices, vertex_next(), vertex_link());
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
  // What from keeps (under 2S of each, and its reserved segments) into
  // into's lists, which give their surplus to the spare stacks.
  while (from.reserved_cells)
    give_id<cell_segment>(into.free_cells, pop_reserved_cell(from), spare_cells, cell_next(), cell_link());
  while (from.free_cells.count) {
    const CellId c = pop_id<cell_segment>(from.free_cells, cell_next());
    give_id<cell_segment>(into.free_cells, c, spare_cells, cell_next(), cell_link());
  }
  while (from.free_vertices.count) {
    const VertexId v = pop_id<vertex_segment>(from.free_vertices, vertex_next());
    give_id<vertex_segment>(into.free_vertices, v, spare_vertices, vertex_next(), vertex_link());
  }
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
  // operation. Cell incarnations go on counting: the tags' pages go back to
  // the OS, and the next cell of every id starts past the highest
  // incarnation they held (tag_floor), so that no handle from before names a
  // cell again. (Nobody holds handles to a small one's cells: its tags stay.)
  if (!is_small) {
    for (CellId c = 0; c < cells.size(); ++c) tag_floor = std::max(tag_floor, incarnation(c));
    tag_floor_end = std::max(tag_floor_end, cells.size());
  }
  cells.clear(!is_small);
  tags.clear(!is_small);
  {
    std::lock_guard lock(spare_mutex);
    released_vertices.clear();
    released_vertex_count.store(0, std::memory_order_relaxed);
  }
  verts.clear(!is_small);
  verts.grow(1);
  verts[0].multiplicity = 1;
  dim = -1;
  n_vertices = n_cells = n_finite_cells = 0;
  flat.clear();
  flat_index.clear();
  basis.clear();
  grid = detail::JumpGrid{};
  filter.clear();
  recent_vertex.store(no_vertex);
  OpContext& c = *seq;
  c.free_cells = c.free_vertices = detail::FreeList{};
  spare_cells.head.store(no_index, std::memory_order_relaxed);
  spare_vertices.head.store(no_index, std::memory_order_relaxed);
  c.fresh_cell = c.fresh_cell_end = c.fresh_vertex = c.fresh_vertex_end = 0;
  c.reserved_head = c.reserved_more = no_index;
  c.reserved_cells = 0;
  c.d_vertices = c.d_cells = c.d_finite_cells = 0;
  c.last_vertex = no_vertex;
}

}  // namespace pdt
