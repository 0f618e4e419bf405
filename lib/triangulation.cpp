// The kernel: Bowyer-Watson insertion located by jump-and-walk, and vertex
// removal by re-triangulating the hole's link (paper §2), written once for
// both the single-threaded triangulation and the engine's workers (§3.2):
// every read of a cell is preceded by a try-lock that is a no-op when the
// context does not lock, and every operation acquires all it needs before it
// changes anything, so a failed try-lock is a clean rollback.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "pdt/error.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::CellRec;
using detail::facet_vertex;
using detail::KPoint;
using detail::orient;
using detail::OpStatus;
using detail::perturbed_incircle;
using detail::perturbed_insphere;

namespace {

constexpr std::uint32_t no_index = 0xFFFFFFFFu;

// Address space reserved for the storage (pages are committed on first touch).
constexpr std::size_t max_cells = std::size_t{1} << 31;
constexpr std::size_t max_vertices = std::size_t{1} << 29;
constexpr std::size_t max_small_cells = std::size_t{1} << 24;
constexpr std::size_t max_small_vertices = std::size_t{1} << 22;

// Pool chunks (paper §3.2): 12 pages of cells, 3 pages of vertices.
constexpr std::uint32_t cell_chunk = 12 * 4096 / sizeof(CellRec);
constexpr std::uint32_t vertex_chunk = 3 * 4096 / sizeof(detail::VertexRec);

std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  x ^= x >> 31;
  return x;
}

std::uint64_t edge_key(VertexId a, VertexId b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t{a} << 32) | b;
}

// Unordered triple of small ids (< 2^21) packed into one key.
std::uint64_t triple_key(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  if (a > b) std::swap(a, b);
  if (b > c) std::swap(b, c);
  if (a > b) std::swap(a, b);
  return (std::uint64_t{a} << 42) | (std::uint64_t{b} << 21) | c;
}

}  // namespace

// ---------------------------------------------------------------------------
// Scratch structures
// ---------------------------------------------------------------------------
namespace detail {

namespace {
// Fibonacci hashing: the table size is a power of two; the high bits of the
// product are well mixed, so fold them down.
inline std::size_t slot_hash(std::uint64_t key, std::size_t mask) {
  std::uint64_t h = key * 0x9E3779B97F4A7C15ull;
  return static_cast<std::size_t>(h ^ (h >> 32)) & mask;
}
}  // namespace

void IdMap::reserve_for(std::size_t entries) {
  std::size_t want = 16;
  while (want < 2 * entries) want <<= 1;
  if (want <= keys_.size()) return;
  clear();
  keys_.assign(want, ~std::uint64_t{0});
  values_.assign(want, 0);
  mask_ = want - 1;
}

void IdMap::clear() {
  for (std::uint32_t s : used_) keys_[s] = ~std::uint64_t{0};
  used_.clear();
}

std::uint32_t IdMap::get_or_insert(std::uint64_t key, std::uint32_t value, bool* inserted) {
  if (2 * (used_.size() + 1) > keys_.size()) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> old;
    old.reserve(used_.size());
    for (std::uint32_t s : used_) old.emplace_back(keys_[s], values_[s]);
    std::size_t want = std::max<std::size_t>(16, keys_.size() * 2);
    keys_.assign(want, ~std::uint64_t{0});
    values_.assign(want, 0);
    mask_ = want - 1;
    used_.clear();
    for (auto& [k, v] : old) get_or_insert(k, v);
  }
  std::size_t s = slot_hash(key, mask_);
  while (true) {
    if (keys_[s] == key) {
      if (inserted) *inserted = false;
      return values_[s];
    }
    if (keys_[s] == ~std::uint64_t{0}) {
      keys_[s] = key;
      values_[s] = value;
      used_.push_back(static_cast<std::uint32_t>(s));
      if (inserted) *inserted = true;
      return value;
    }
    s = (s + 1) & mask_;
  }
}

std::uint32_t IdMap::find(std::uint64_t key) const {
  if (keys_.empty()) return no_index;
  std::size_t s = slot_hash(key, mask_);
  while (true) {
    if (keys_[s] == key) return values_[s];
    if (keys_[s] == ~std::uint64_t{0}) return no_index;
    s = (s + 1) & mask_;
  }
}

std::size_t JumpGrid::slot_of(const KPoint& p) const {
  int idx[3];
  const double c[3] = {p.x(), p.y(), p.z()};
  for (int a = 0; a < 3; ++a) {
    // Halves, so the difference cannot overflow even for the largest doubles;
    // written so that NaN lands in slot 0.
    double t = (0.5 * c[a] - lo[a]) * inv[a];
    idx[a] = !(t > 0) ? 0 : (t >= res - 1 ? res - 1 : static_cast<int>(t));
  }
  return (static_cast<std::size_t>(idx[2]) * res + idx[1]) * res + idx[0];
}

}  // namespace detail

OpContext::OpContext(std::uint32_t id_, bool locking_)
    : id(id_), locking(locking_), rng(0x9E3779B97F4A7C15ull ^ mix64(id_)) {
  facet_map.reserve_for(64);
  link_index.reserve_for(64);
  held_shared.reserve(64);
  held_exclusive.reserve(64);
}
OpContext::~OpContext() = default;

// ---------------------------------------------------------------------------
// Impl basics: pools, counters, locks
// ---------------------------------------------------------------------------
Triangulation::Impl::Impl(bool small_triangulation)
    : cells(small_triangulation ? max_small_cells : max_cells),
      marks(small_triangulation ? max_small_cells : max_cells),
      verts(small_triangulation ? max_small_vertices : max_vertices),
      is_small(small_triangulation),
      seq(std::make_unique<OpContext>(1, false)) {
  verts.grow(1);  // vertex 0: the infinite vertex
  verts[0].multiplicity = 1;
}

Triangulation::Impl::~Impl() = default;

CellId Triangulation::Impl::alloc_cell(OpContext& ctx) {
  CellId c;
  if (ctx.free_cells.head != no_index) {
    c = ctx.free_cells.head;
    ctx.free_cells.head = cells[c].n[0];
    if (--ctx.free_cells.count == 0) ctx.free_cells.tail = no_index;
  } else {
    if (ctx.fresh_cell == ctx.fresh_cell_end) {
      std::size_t first = cells.grow(cell_chunk);
      marks.ensure_size(first + cell_chunk);
      for (std::size_t i = first; i < first + cell_chunk; ++i) cells[i].v[0] = no_vertex;  // not live yet
      ctx.fresh_cell = static_cast<std::uint32_t>(first);
      ctx.fresh_cell_end = static_cast<std::uint32_t>(first + cell_chunk);
    }
    c = ctx.fresh_cell++;
  }
  marks[c] = 0;
  ++ctx.d_cells;
  return c;
}

void Triangulation::Impl::free_cell(OpContext& ctx, CellId c) {
  cells[c].v[0] = no_vertex;
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
  r.p = p;
  r.cell = no_cell;
  r.multiplicity = 1;
  r.stamp.store((std::uint64_t{ctx.id} << 40) | ++ctx.vertex_counter, std::memory_order_release);
  ++ctx.d_vertices;
  ctx.last_vertex = v;
  return v;
}

void Triangulation::Impl::free_vertex(OpContext& ctx, VertexId v) {
  VertexRec& r = verts[v];
  r.multiplicity = 0;
  r.stamp.store(0, std::memory_order_relaxed);
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
  // engine.cpp) or when they grow large: three shared counters updated after
  // every operation would be one cache line bouncing between all workers.
  constexpr std::int64_t kFoldAt = 4096;
  if (!ctx.locking || ctx.d_cells >= kFoldAt || ctx.d_cells <= -kFoldAt) fold_counters(ctx);
}

void Triangulation::Impl::fold_counters(OpContext& ctx) {
  if (ctx.d_vertices) n_vertices.fetch_add(ctx.d_vertices, std::memory_order_relaxed);
  if (ctx.d_cells) n_cells.fetch_add(ctx.d_cells, std::memory_order_relaxed);
  if (ctx.d_finite_cells) n_finite_cells.fetch_add(ctx.d_finite_cells, std::memory_order_relaxed);
  ctx.d_vertices = ctx.d_cells = ctx.d_finite_cells = 0;
}

bool Triangulation::Impl::lock_shared(OpContext& ctx, VertexId v) {
  if (!ctx.locking || v == 0) return true;
  std::atomic<std::int32_t>& w = verts[v].lock;
  std::int32_t cur = w.load(std::memory_order_relaxed);
  if (cur == -static_cast<std::int32_t>(ctx.id)) return true;
  for (VertexId h : ctx.held_shared)
    if (h == v) return true;
  while (cur >= 0)
    if (w.compare_exchange_weak(cur, cur + 1, std::memory_order_acquire, std::memory_order_relaxed)) {
      ctx.held_shared.push_back(v);
      return true;
    }
  return false;
}

bool Triangulation::Impl::lock_exclusive(OpContext& ctx, VertexId v) {
  if (!ctx.locking || v == 0) return true;
  std::atomic<std::int32_t>& w = verts[v].lock;
  const std::int32_t mine = -static_cast<std::int32_t>(ctx.id);
  std::int32_t cur = w.load(std::memory_order_relaxed);
  if (cur == mine) return true;
  auto it = std::find(ctx.held_shared.begin(), ctx.held_shared.end(), v);
  std::int32_t expect = it != ctx.held_shared.end() ? 1 : 0;  // upgrade: we must be the only reader
  if (!w.compare_exchange_strong(expect, mine, std::memory_order_acquire, std::memory_order_relaxed)) return false;
  if (it != ctx.held_shared.end()) {
    *it = ctx.held_shared.back();
    ctx.held_shared.pop_back();
  }
  ctx.held_exclusive.push_back(v);
  return true;
}

bool Triangulation::Impl::lock_cell_exclusive(OpContext& ctx, CellId c) {
  const VertexId* v = cells[c].v;
  return lock_exclusive(ctx, v[0]) && lock_exclusive(ctx, v[1]) && lock_exclusive(ctx, v[2]) &&
         lock_exclusive(ctx, v[3]);
}

void Triangulation::Impl::release_all(OpContext& ctx) {
  for (VertexId v : ctx.held_exclusive) verts[v].lock.store(0, std::memory_order_release);
  for (VertexId v : ctx.held_shared) verts[v].lock.fetch_sub(1, std::memory_order_release);
  ctx.held_exclusive.clear();
  ctx.held_shared.clear();
}

void Triangulation::Impl::clear() {
  // A small (per-removal) triangulation keeps its pages: it is cleared per operation.
  cells.clear(!is_small);
  marks.clear(!is_small);
  verts.clear(!is_small);
  verts.grow(1);
  verts[0].multiplicity = 1;
  dim = -1;
  n_vertices = n_cells = n_finite_cells = 0;
  flat.clear();
  flat_index.clear();
  basis = {no_vertex, no_vertex, no_vertex};
  grid = detail::JumpGrid{};
  recent_vertex.store(no_vertex);
  OpContext& c = *seq;
  c.free_cells = c.free_vertices = detail::FreeList{};
  c.fresh_cell = c.fresh_cell_end = c.fresh_vertex = c.fresh_vertex_end = 0;
  c.d_vertices = c.d_cells = c.d_finite_cells = 0;
  c.last_vertex = no_vertex;
}

// ---------------------------------------------------------------------------
// Location
// ---------------------------------------------------------------------------
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
    VertexId v = grid_lookup(p);
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
  for (VertexId v = 1; v < bound; ++v)
    if (verts[v].multiplicity > 0) return v;
  return no_vertex;
}

CellId Triangulation::Impl::walk(OpContext& ctx, const KPoint& p, CellId c, bool* outside) const {
  // Visibility walk (Devillers, Pion, Teillaud): cross a facet that p is
  // strictly beyond; the facets are tried from a random one so the walk cannot
  // cycle. Never stops in a finite cell that p is outside of.
  Impl& self = *const_cast<Impl*>(this);
  CellId prev = no_cell;
  std::uint64_t r = ctx.next_random();
  while (true) {
    const CellRec& cr = cells[c];
    const KPoint* q[4] = {&pt(cr.v[0]), &pt(cr.v[1]), &pt(cr.v[2]), &pt(cr.v[3])};
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
      if (orient(*a[0], *a[1], *a[2], *a[3]) < 0) {
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

bool Triangulation::Impl::in_conflict(CellId c, const KPoint& p) const {
  const CellRec& cr = cells[c];
  int k = index_of(c, 0);
  if (k < 0) return perturbed_insphere(pt(cr.v[0]), pt(cr.v[1]), pt(cr.v[2]), pt(cr.v[3]), p) > 0;
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
  int o = orient(a, b, d, p);
  if (o != 0) return o > 0;
  return perturbed_incircle(a, b, d, p) > 0;
}

// ---------------------------------------------------------------------------
// Insertion
// ---------------------------------------------------------------------------
OpStatus Triangulation::Impl::insert(OpContext& ctx, const KPoint& p, VertexId hint, InsertResult& out) {
  if (dim.load(std::memory_order_acquire) < 3) {
    if (ctx.locking) return OpStatus::needs_global;
    out = insert_flat(ctx, p);
    ctx.result_stamp = verts[out.vertex].stamp.load(std::memory_order_relaxed);
    ++ctx.stats.insertions;
    fold_counters(ctx);
    return OpStatus::done;
  }
  auto rollback = [&] {
    release_all(ctx);
    return OpStatus::rollback;
  };
  VertexId s = start_vertex(ctx, p, hint);
  if (s == no_vertex) return rollback();
  // Hold s's cell (stable: it contains s, which we hold), then walk.
  CellId c = verts[s].cell;
  for (int i = 0; i < 4; ++i)
    if (!lock_shared(ctx, cells[c].v[i])) return rollback();
  if (int k = index_of(c, 0); k >= 0) {
    std::uint32_t nw = cells[c].n[k];
    c = nw >> 2;
    if (!lock_shared(ctx, cells[c].v[nw & 3])) return rollback();
  }
  bool outside = false;
  c = walk(ctx, p, c, &outside);
  if (c == no_cell) return rollback();
  if (!outside) {
    const CellRec& cr = cells[c];
    for (int i = 0; i < 4; ++i) {
      VertexId w = cr.v[i];
      if (w != 0 && pt(w) == p) {
        if (!lock_exclusive(ctx, w)) return rollback();
        ++verts[w].multiplicity;
        ctx.result_stamp = verts[w].stamp.load(std::memory_order_relaxed);
        ++ctx.stats.duplicates;
        ++ctx.stats.insertions;
        release_all(ctx);
        out = {w, false};
        return OpStatus::done;
      }
    }
  }
  if (!lock_cell_exclusive(ctx, c)) return rollback();
  if (find_cavity(ctx, p, c) != OpStatus::done) return rollback();
  VertexId v = alloc_vertex(ctx, p);
  ctx.result_stamp = verts[v].stamp.load(std::memory_order_relaxed);
  fill_cavity(ctx, v);
  grid_update(ctx, v);
  // A start for contexts that know no vertex yet; refreshed rarely (shared line).
  if ((ctx.vertex_counter & 63) == 1) recent_vertex.store(v, std::memory_order_relaxed);
  ++ctx.stats.insertions;
  release_all(ctx);
  end_op_counters(ctx);
  out = {v, true};
  return OpStatus::done;
}

OpStatus Triangulation::Impl::find_cavity(OpContext& ctx, const KPoint& p, CellId c0) {
  // Bowyer-Watson: the cells whose (perturbed) circumsphere contains p form a
  // connected, star-shaped cavity; search it breadth first. c0 is held
  // exclusively; each cell joining the cavity is locked exclusively before
  // its own neighbours are read.
  const std::uint64_t in = ctx.next_stamp(), out = in + 1;
  std::vector<CellId>& cavity = ctx.cavity;
  cavity.clear();
  ctx.boundary.clear();
  marks[c0] = in;
  cavity.push_back(c0);
  for (std::size_t idx = 0; idx < cavity.size(); ++idx) {
    CellId c = cavity[idx];
    for (int i = 0; i < 4; ++i) {
      std::uint32_t nw = cells[c].n[i];
      CellId nb = nw >> 2;
      std::uint64_t m = marks[nb];
      if (m == in) continue;
      if (m != out) {
        if (in_conflict(nb, p)) {
          if (!lock_exclusive(ctx, cells[nb].v[nw & 3])) return OpStatus::rollback;
          marks[nb] = in;
          cavity.push_back(nb);
          continue;
        }
        marks[nb] = out;
      }
      OpContext::BoundaryFacet bf;
      std::memcpy(bf.v, cells[c].v, sizeof bf.v);
      bf.outer = nw;
      bf.facet = i;
      ctx.boundary.push_back(bf);
    }
  }
  return OpStatus::done;
}

void Triangulation::Impl::fill_cavity(OpContext& ctx, VertexId v) {
  // Replace the cavity by the cone from v over its boundary. Cavity cells are
  // recycled first so the new cells reuse their memory.
  for (CellId c : ctx.cavity) {
    if (!cell_infinite(c)) --ctx.d_finite_cells;
    free_cell(ctx, c);
  }
  detail::IdMap& edges = ctx.facet_map;
  edges.reserve_for(3 * ctx.boundary.size());
  edges.clear();
  for (OpContext::BoundaryFacet& bf : ctx.boundary) {
    bf.v[bf.facet] = v;
    CellId nc = alloc_cell(ctx);
    CellRec& r = cells[nc];
    std::memcpy(r.v, bf.v, sizeof r.v);
    set_adjacency(nc, bf.facet, bf.outer >> 2, static_cast<int>(bf.outer & 3));
    bool finite = true;
    for (int k = 0; k < 4; ++k) {
      if (r.v[k] == 0) finite = false;
      set_vertex_cell(r.v[k], nc);
    }
    if (finite) ++ctx.d_finite_cells;
    // The three facets through v: each is identified by the cavity-boundary
    // edge it contains; the two new cells on that edge are neighbours.
    for (int k = 0; k < 4; ++k) {
      if (k == bf.facet) continue;
      int a = -1, b = -1;
      for (int t = 0; t < 4; ++t) {
        if (t == k || t == bf.facet) continue;
        (a < 0 ? a : b) = t;
      }
      bool inserted = false;
      std::uint32_t val = edges.get_or_insert(edge_key(r.v[a], r.v[b]), 4 * nc + static_cast<std::uint32_t>(k), &inserted);
      if (!inserted) set_adjacency(nc, k, val >> 2, static_cast<int>(val & 3));
    }
  }
  ctx.stats.cells_created_by_insert += ctx.boundary.size();
}

// ---------------------------------------------------------------------------
// Dimension < 3: vertices kept in a list until 4 are affinely independent.
// Single-threaded only (the engine runs these with the world stopped).
// ---------------------------------------------------------------------------
std::uint64_t Triangulation::Impl::point_hash(const KPoint& p) {
  std::uint64_t h = 0;
  const double c[3] = {p.x(), p.y(), p.z()};
  for (double d : c) {
    std::uint64_t bits;
    std::memcpy(&bits, &d, sizeof bits);
    h = mix64(h ^ bits);
  }
  return h;
}

VertexId Triangulation::Impl::find_flat(const KPoint& p) const {
  auto it = flat_index.find(point_hash(p));
  if (it == flat_index.end()) return no_vertex;
  for (VertexId w : it->second)
    if (pt(w) == p) return w;
  return no_vertex;
}

InsertResult Triangulation::Impl::insert_flat(OpContext& ctx, const KPoint& p) {
  if (VertexId w = find_flat(p); w != no_vertex) {
    ++verts[w].multiplicity;
    ++ctx.stats.duplicates;
    return {w, false};
  }
  bool raises_to_3d = dim == 2 && orient(pt(basis[0]), pt(basis[1]), pt(basis[2]), p) != 0;
  VertexId v = alloc_vertex(ctx, p);
  if (raises_to_3d) {
    build_3d(ctx, v);
    return {v, true};
  }
  verts[v].cell = static_cast<CellId>(flat.size());
  flat.push_back(v);
  flat_index[point_hash(p)].push_back(v);
  if (dim == -1) {
    basis[0] = v;
    dim = 0;
  } else if (dim == 0) {
    basis[1] = v;
    dim = 1;
  } else if (dim == 1 && !CGAL::collinear(pt(basis[0]), pt(basis[1]), p)) {
    basis[2] = v;
    dim = 2;
  }
  return {v, true};
}

void Triangulation::Impl::recompute_basis() {
  basis = {no_vertex, no_vertex, no_vertex};
  dim = -1;
  for (VertexId v : flat) {
    if (dim == -1) {
      basis[0] = v;
      dim = 0;
    } else if (dim == 0) {
      basis[1] = v;
      dim = 1;
    } else if (dim == 1 && !CGAL::collinear(pt(basis[0]), pt(basis[1]), pt(v))) {
      basis[2] = v;
      dim = 2;
      break;
    }
  }
}

void Triangulation::Impl::remove_flat(OpContext& ctx, VertexId v) {
  std::size_t pos = verts[v].cell;
  flat[pos] = flat.back();
  verts[flat[pos]].cell = static_cast<CellId>(pos);
  flat.pop_back();
  auto it = flat_index.find(point_hash(pt(v)));
  auto& bucket = it->second;
  bucket.erase(std::find(bucket.begin(), bucket.end(), v));
  if (bucket.empty()) flat_index.erase(it);
  bool was_basis = std::find(basis.begin(), basis.end(), v) != basis.end();
  free_vertex(ctx, v);
  if (ctx.last_vertex == no_vertex && !flat.empty()) ctx.last_vertex = flat.back();
  if (was_basis) recompute_basis();
}

void Triangulation::Impl::build_3d(OpContext& ctx, VertexId apex) {
  // First tetrahedron: the basis and the apex, positively oriented; then the
  // 4 infinite cells over its facets. Then every other listed vertex is
  // inserted; the result does not depend on that order.
  VertexId t[4] = {basis[0], basis[1], basis[2], apex};
  if (orient(pt(t[0]), pt(t[1]), pt(t[2]), pt(t[3])) < 0) std::swap(t[0], t[1]);
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
  // Link by matching facets (5 cells: quadratic is fine).
  for (int a = 0; a < 5; ++a)
    for (int fa = 0; fa < 4; ++fa)
      for (int b = a + 1; b < 5; ++b)
        for (int fb = 0; fb < 4; ++fb) {
          const VertexId* va = cells[all[a]].v;
          const VertexId* vb = cells[all[b]].v;
          if (triple_key(va[facet_vertex[fa][0]], va[facet_vertex[fa][1]], va[facet_vertex[fa][2]]) ==
              triple_key(vb[facet_vertex[fb][0]], vb[facet_vertex[fb][1]], vb[facet_vertex[fb][2]]))
            set_adjacency(all[a], fa, all[b], fb);
        }
  for (int i = 0; i < 4; ++i) verts[t[i]].cell = all[0];
  dim.store(3, std::memory_order_release);
  std::vector<VertexId> rest;
  rest.swap(flat);
  flat_index.clear();
  basis = {no_vertex, no_vertex, no_vertex};
  rest.erase(std::remove_if(rest.begin(), rest.end(),
                            [&](VertexId v) { return v == t[0] || v == t[1] || v == t[2] || v == t[3]; }),
             rest.end());
  // Insert the rest in Morton order, each walk starting from the previous
  // vertex: short walks without the jump grid, which must not name a vertex
  // before it is in the triangulation.
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (VertexId v : rest) {
    const double c[3] = {pt(v).x(), pt(v).y(), pt(v).z()};
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
  }
  auto morton = [&](VertexId v) {
    const double c[3] = {pt(v).x(), pt(v).y(), pt(v).z()};
    std::uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      double half_ext = 0.5 * hi[a] - 0.5 * lo[a];  // halves: no overflow
      double t = half_ext > 0 ? (0.5 * c[a] - 0.5 * lo[a]) / half_ext * 1023.0 : 0.0;
      auto q = static_cast<std::uint64_t>(t > 0 && t <= 1023.0 ? t : 0.0);
      for (int b = 0; b < 10; ++b) key |= ((q >> b) & 1u) << (3 * b + a);
    }
    return key;
  };
  std::vector<std::pair<std::uint64_t, VertexId>> order;
  order.reserve(rest.size());
  for (VertexId v : rest) order.emplace_back(morton(v), v);
  std::sort(order.begin(), order.end());
  grid = detail::JumpGrid{};
  VertexId prev = apex;
  for (auto [key, v] : order) {
    bool outside = false;
    CellId c = walk(ctx, pt(v), finite_cell_of(prev), &outside);
    find_cavity(ctx, pt(v), c);
    fill_cavity(ctx, v);
    prev = v;
  }
  fold_counters(ctx);
  grid_rebuild();
  ctx.last_vertex = apex;
  recent_vertex.store(apex, std::memory_order_relaxed);
}

void Triangulation::Impl::drop_to_flat(OpContext& ctx) {
  // The live vertices are coplanar (or fewer than 4): forget the cells.
  // Cells go back to this context's pool (other pools' free lists stay valid).
  for (CellId c = 0; c < cells.size(); ++c) {
    if (!cell_alive(c)) continue;
    if (!cell_infinite(c)) --ctx.d_finite_cells;
    free_cell(ctx, c);
  }
  flat.clear();
  flat_index.clear();
  grid = detail::JumpGrid{};
  for (VertexId v = 1; v < verts.size(); ++v) {
    if (verts[v].multiplicity == 0) continue;
    verts[v].cell = static_cast<CellId>(flat.size());
    flat.push_back(v);
    flat_index[point_hash(pt(v))].push_back(v);
  }
  recompute_basis();
  ctx.last_vertex = flat.empty() ? no_vertex : flat.back();
  recent_vertex.store(no_vertex, std::memory_order_relaxed);
}

// ---------------------------------------------------------------------------
// Removal (paper §2.2)
// ---------------------------------------------------------------------------
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
    os << "cannot remove vertex " << v << ": it is not in the triangulation (already removed, or never inserted)";
    throw Error(ErrorCode::unknown_vertex, os.str());
  }
  if (verts[v].multiplicity > 1) {
    --verts[v].multiplicity;
    ++ctx.stats.removals;
    release_all(ctx);
    out = RemoveResult::multiplicity_lowered;
    return OpStatus::done;
  }
  if (dim.load(std::memory_order_acquire) < 3) {
    if (ctx.locking) {
      release_all(ctx);
      return OpStatus::needs_global;
    }
    remove_flat(ctx, v);
  } else {
    OpStatus s = remove_3d(ctx, v);
    if (s != OpStatus::done) {
      release_all(ctx);
      return s;
    }
  }
  ++ctx.stats.removals;
  release_all(ctx);
  end_op_counters(ctx);
  out = RemoveResult::removed;
  return OpStatus::done;
}

void Triangulation::Impl::collect_incident_cells(OpContext& ctx, VertexId v, std::vector<CellId>& out) {
  // The visited set is the context's own, not `marks`: holding v keeps these
  // cells from changing, but not from being marked by an insertion next door
  // that holds a facet of one of them (opposite v) and tests it for conflict.
  detail::IdMap& seen = ctx.visited;
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
      if (inserted) out.push_back(nb);
    }
  }
}

OpStatus Triangulation::Impl::remove_3d(OpContext& ctx, VertexId v) {
  // v is held exclusively, so every cell incident to v is stable.
  std::vector<CellId>& hole = ctx.cavity;
  collect_incident_cells(ctx, v, hole);
  // The link: the hole's vertices but v. Finite ones get small ids 1, 2, ...
  // in the order met (their ids in the small triangulation); the infinite
  // vertex is 0 in both.
  ctx.link.clear();
  ctx.link_index.reserve_for(hole.size() * 3);
  ctx.link_index.clear();
  ctx.link_index.get_or_insert(0, 0);
  for (CellId c : hole) {
    const CellRec& r = cells[c];
    for (int i = 0; i < 4; ++i) {
      VertexId w = r.v[i];
      if (w == v || w == 0) continue;
      bool inserted = false;
      ctx.link_index.get_or_insert(w, static_cast<std::uint32_t>(ctx.link.size() + 1), &inserted);
      if (inserted) {
        if (!lock_exclusive(ctx, w)) return OpStatus::rollback;
        ctx.link.push_back(w);
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
    bool flat_after = true;
    if (ctx.link.size() >= 4) {
      const KPoint* b[3] = {&pt(ctx.link[0]), &pt(ctx.link[1]), nullptr};
      for (std::size_t i = 2; i < ctx.link.size() && flat_after; ++i) {
        const KPoint& q = pt(ctx.link[i]);
        if (!b[2]) {
          if (!CGAL::collinear(*b[0], *b[1], q)) b[2] = &q;
        } else if (orient(*b[0], *b[1], *b[2], q) != 0) {
          flat_after = false;
        }
      }
    }
    if (flat_after) {
      if (ctx.locking) return OpStatus::needs_global;
      free_vertex(ctx, v);
      drop_to_flat(ctx);
      return OpStatus::done;
    }
  }

  // The small triangulation of the link's finite vertices (paper §2.2). The
  // perturbation makes it contain every facet of the hole's boundary.
  if (!ctx.small) ctx.small = std::make_unique<Impl>(true);
  Impl& s = *ctx.small;
  s.clear();
  InsertResult ignored;
  for (VertexId w : ctx.link) s.insert(*s.seq, pt(w), s.seq->last_vertex, ignored);
  ctx.stats.cells_touched_by_remove += static_cast<std::uint64_t>(s.n_cells.load());

  if (s.dim < 3)
    fill_hole_flat_link(ctx, v);
  else
    fill_hole(ctx, v);

  if (grid.slot_count) {
    std::size_t slot = grid.slot_of(pt(v));
    if (grid.get(slot) == v) grid.set(slot, ctx.link.front());
  }
  free_vertex(ctx, v);
  ctx.last_vertex = ctx.link.front();
  return OpStatus::done;
}

void Triangulation::Impl::fill_hole_flat_link(OpContext& ctx, VertexId v) {
  // v is a hull vertex whose finite link lies in a plane P: after removal the
  // hull is flat on v's side, and the hole is filled by infinite cells over
  // the (unchanged) triangles of P. A finite hole cell becomes such a cell by
  // putting the infinite vertex in v's place; v was beyond P, so orientation
  // is preserved. The infinite hole cells disappear; their outer neighbours
  // become the new cells' neighbours.
  const std::vector<CellId>& hole = ctx.cavity;
  for (CellId h : hole) {
    if (cell_infinite(h)) continue;
    cells[h].v[index_of(h, v)] = 0;
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
    if (index_of(h, v) >= 0) free_cell(ctx, h);
}

void Triangulation::Impl::fill_hole(OpContext& ctx, VertexId v) {
  Impl& s = *ctx.small;
  OpContext& sctx = *s.seq;
  const std::vector<CellId>& hole = ctx.cavity;
  // Boundary facets of the hole, keyed by their unordered small-id triple.
  ctx.boundary.clear();
  detail::IdMap& facets = ctx.facet_map;
  facets.reserve_for(hole.size());
  facets.clear();
  for (CellId h : hole) {
    int k = index_of(h, v);
    OpContext::BoundaryFacet bf;
    std::memcpy(bf.v, cells[h].v, sizeof bf.v);
    bf.outer = cells[h].n[k];
    bf.facet = k;
    std::uint32_t a = ctx.link_index.find(bf.v[facet_vertex[k][0]]);
    std::uint32_t b = ctx.link_index.find(bf.v[facet_vertex[k][1]]);
    std::uint32_t c = ctx.link_index.find(bf.v[facet_vertex[k][2]]);
    facets.get_or_insert(triple_key(a, b, c), static_cast<std::uint32_t>(ctx.boundary.size()));
    ctx.boundary.push_back(bf);
  }
  // A small cell on the inner side of the first boundary facet: it lists the
  // facet in the same cyclic order as the hole cell does.
  const OpContext::BoundaryFacet& f0 = ctx.boundary.front();
  std::uint32_t t0[3];
  for (int j = 0; j < 3; ++j) t0[j] = ctx.link_index.find(f0.v[facet_vertex[f0.facet][j]]);
  s.collect_incident_cells(sctx, t0[0] != 0 ? t0[0] : t0[1], ctx.star);
  CellId start = no_cell;
  for (CellId sc : ctx.star) {
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
  const std::uint64_t seen = sctx.next_stamp();
  std::vector<CellId>& inside = ctx.small_inside;
  inside.clear();
  std::size_t small_bound = s.cells.size();
  if (ctx.small_facet_bf.size() < 4 * small_bound) ctx.small_facet_bf.resize(4 * small_bound);
  if (ctx.small_to_new.size() < small_bound) ctx.small_to_new.resize(small_bound);
  s.marks[start] = seen;
  inside.push_back(start);
  std::size_t matched = 0;
  for (std::size_t idx = 0; idx < inside.size(); ++idx) {
    CellId sc = inside[idx];
    const CellRec& r = s.cells[sc];
    for (int m = 0; m < 4; ++m) {
      std::uint32_t b = facets.find(triple_key(r.v[facet_vertex[m][0]], r.v[facet_vertex[m][1]], r.v[facet_vertex[m][2]]));
      ctx.small_facet_bf[4 * sc + m] = b;
      if (b != no_index) {
        ++matched;
        continue;
      }
      CellId nb = r.n[m] >> 2;
      if (s.marks[nb] != seen) {
        s.marks[nb] = seen;
        inside.push_back(nb);
      }
    }
  }
  if (matched != ctx.boundary.size())
    throw std::logic_error("pdt: removal: the link triangulation does not match the hole");

  // Sew: hole cells out, the inside small cells in, with big vertex ids.
  for (CellId h : hole) {
    if (!cell_infinite(h)) --ctx.d_finite_cells;
    free_cell(ctx, h);
  }
  for (CellId sc : inside) ctx.small_to_new[sc] = alloc_cell(ctx);
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
      std::uint32_t b = ctx.small_facet_bf[4 * sc + m];
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

// ---------------------------------------------------------------------------
// Jump grid
// ---------------------------------------------------------------------------
void Triangulation::Impl::grid_update(OpContext& ctx, VertexId v) {
  if (is_small) return;
  // Single-threaded: resize as the vertex count doubles. Engine workers never
  // rebuild here: the engine regrows the grid itself with the world stopped
  // (EngineState::ensure_grid) and sets built_for out of reach meanwhile.
  if (!ctx.locking && static_cast<std::size_t>(n_vertices.load(std::memory_order_relaxed) + ctx.d_vertices) >=
                          2 * grid.built_for + 64) {
    fold_counters(ctx);
    grid_rebuild();
    return;
  }
  if (grid.slot_count) grid.set(grid.slot_of(pt(v)), v);
}

VertexId Triangulation::Impl::grid_lookup(const KPoint& p) const {
  // p's slot, else the nearest filled slot within two shells around it.
  std::size_t s = grid.slot_of(p);
  VertexId v = grid.get(s);
  if (v != no_vertex) return v;
  const int res = grid.res;
  const int x = static_cast<int>(s % res), y = static_cast<int>((s / res) % res), z = static_cast<int>(s / res / res);
  for (int r = 1; r <= 2; ++r)
    for (int dz = -r; dz <= r; ++dz)
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
          int a = x + dx, b = y + dy, c = z + dz;
          if (a < 0 || b < 0 || c < 0 || a >= res || b >= res || c >= res) continue;
          v = grid.get((static_cast<std::size_t>(c) * res + b) * res + a);
          if (v != no_vertex) return v;
        }
  return no_vertex;
}

void Triangulation::Impl::grid_rebuild(std::size_t slots) {
  // Counts the live vertices itself: n_vertices lags while engine workers
  // hold unfolded deltas (this runs with the world stopped then).
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  const std::size_t bound = verts.size();
  std::size_t n = 0;
  for (VertexId v = 1; v < bound; ++v) {
    if (verts[v].multiplicity == 0) continue;
    ++n;
    const KPoint& p = pt(v);
    const double c[3] = {p.x(), p.y(), p.z()};
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
  }
  // About 2 vertices per slot right after a rebuild, so few slots are empty.
  // Built aside and moved in: an allocation failure leaves the old grid.
  const std::size_t want = std::min<std::size_t>(slots ? slots : std::max<std::size_t>(1, n / 2), std::size_t{1} << 30);
  detail::JumpGrid g;
  g.res = std::max(1, static_cast<int>(std::cbrt(static_cast<double>(want))));
  for (int a = 0; a < 3; ++a) {
    g.lo[a] = 0.5 * lo[a];  // see slot_of
    double half_ext = 0.5 * hi[a] - 0.5 * lo[a];
    g.inv[a] = half_ext > 0 && std::isfinite(g.res / half_ext) ? g.res / half_ext : 0;
  }
  g.slot_count = static_cast<std::size_t>(g.res) * g.res * g.res;
  g.slots = std::make_unique<std::atomic<VertexId>[]>(g.slot_count);
  for (std::size_t s = 0; s < g.slot_count; ++s) g.set(s, no_vertex);
  for (VertexId v = 1; v < bound; ++v)
    if (verts[v].multiplicity > 0) g.set(g.slot_of(pt(v)), v);
  g.built_for = n;
  grid = std::move(g);
}

}  // namespace pdt
