// SPDX-License-Identifier: MIT
// pdt::Engine's public API: attaching, submission, drain, statistics. The
// scheduler is in engine_scheduler.cpp, running an operation in
// engine_execute.cpp; the rooms are listed in engine_state.hpp.
#include "pdt/engine.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include "engine_state.hpp"
#include "for_range.hpp"
#include "pdt/error.hpp"
#include "point_checks.hpp"
#include "spatial_order.hpp"

namespace pdt {

using detail::EngineState;
using detail::OpRecord;

namespace detail {

namespace {
// An engine destroyed from its own work cannot be torn down: its state is
// kept here, reachable (not a leak), for the rest of the process.
void keep_orphan(EngineState* e) {
  static std::mutex m;
  static auto* orphans = new std::vector<EngineState*>();  // never freed, on purpose
  std::lock_guard lock(m);
  try {
    orphans->push_back(e);
  } catch (...) {
    // No room to keep it: it stays allocated, unreachable.
  }
}
}  // namespace

// ---------------------------------------------------------------------------
// Attaching and detaching
// ---------------------------------------------------------------------------
EngineState::EngineState(Triangulation& t, const Box& d, EngineOptions o, unsigned nw, unsigned b,
                         tbb::task_arena* a)
    : impl(impl_of(t)),
      domain(d),
      opts(o),
      attached(tbb::task_arena::attach{}),
      arena(a ? a : &attached),
      nworkers(nw),
      partition(d, b, nw),
      blocks(std::make_unique<Block[]>(partition.blocks())),
      nonempty(partition.blocks()),
      submitted(std::make_unique<SubmitCount[]>(submit_shards)),
      world(nw) {
  // Everything that may fail comes first; the triangulation is touched last.
  for (std::uint32_t i = 0; i < partition.blocks(); ++i) blocks[i].home = partition.home_of(i);
  sleepers.reserve(nworkers);
  if (opts.stealing && opts.rebalance && nworkers > 1)
    recut_keys.reserve(std::size_t{partition.blocks()} * recut_sample_per_block);
  workers.reserve(nworkers);
  for (unsigned i = 0; i < nworkers; ++i) {
    workers.push_back(std::make_unique<Worker>(i, impl.new_context_id(), opts));
    // One worker: nothing runs beside it but global steps, which wait for it
    // to pause, and outside readers of vertices (OpContext::alone).
    workers.back()->ctx->alone = workers.back()->ctx->outside_readers = nworkers == 1;
    workers.back()->spare = records.acquire();
  }
  kernel_hook = [this](const Changes& c) {
    try {
      if (user_hook) user_hook(c);
    } catch (...) {
      record_client_error(std::current_exception());
    }
  };
  // The triangulation's own grid serves while it was built for at least half
  // of the live vertices and at most four times them (the kernel keeps it
  // so, growing and shrinking; an earlier engine may not have): rebuilding it for every
  // engine made each one cost time in proportion to the mesh, so that many
  // short-lived engines on a large mesh spent most of their time here. Else
  // built now, while grid_growth still says kernel: a tree that follows the
  // vertices there are (the engine's own rebuilds use equal slots, cut again
  // where crowded).
  const auto live = static_cast<std::size_t>(std::max<std::int64_t>(0, impl.n_vertices.load()));
  if (impl.grid.slot_count != 0 && 2 * impl.grid.built_for >= live && !impl.grid.shrunk_since_build(live)) {
    grid_grow_at.store(2 * impl.vertex_ids_in_use() + 1024, std::memory_order_relaxed);
    grid_built_for.store(impl.grid.built_for, std::memory_order_relaxed);
    grid_may_grow.store(impl.vertex_ids_in_use() / 2 < std::max<std::size_t>(opts.grid_slots, 1),
                        std::memory_order_relaxed);
  } else {
    ensure_grid(false, false, impl.grid.shrunk_since_build(live));  // built aside: a failure leaves the old grid
  }
  bodies.reserve(nworkers);
  for (auto& w : workers) {
    bodies.push_back(body(*w));  // room reserved: no throw after the frame exists
    w->handle = bodies.back().handle;
  }
  idle_count.store(static_cast<int>(nworkers));
  const std::int64_t now = detail::steady_ns();
  for (auto& w : workers) w->begin_idle(now);  // until its body first runs
  // Every point the workers insert lies in the domain: in the filter's box
  // from now on, which they only read (box_filter.hpp, Impl::insert).
  impl.filter.extend(detail::to_kpoint(domain.lo));
  impl.filter.extend(detail::to_kpoint(domain.hi));
  impl.grid_growth = Triangulation::Impl::GridGrowth::engine;
  impl.seq->hook = nullptr;  // the engine's hook (set_change_hook) reports its global steps
  impl.seq->report_destroyed = false;
  impl.seq->outside_readers = true;  // global steps: see OpContext::outside_readers
}

EngineState::~EngineState() {
  for (auto& b : bodies) b.handle.destroy();
  // Give the workers' pools and statistics back to the triangulation.
  for (auto& w : workers) {
    publish_batch_done(*w);  // done at each claim's end; nothing is left here after a drain
    impl.merge_pools(*impl.seq, *w->ctx);
    impl.seq->stats += w->ctx->stats;
  }
  impl.seq->hook = impl.hook ? &impl.hook : nullptr;
  impl.seq->report_destroyed = impl.report_destroyed;
  impl.seq->outside_readers = false;
  impl.grid_growth = Triangulation::Impl::GridGrowth::kernel;
}

void EngineState::record_client_error(std::exception_ptr e) {
  client_errors.fetch_add(1, std::memory_order_relaxed);
  std::lock_guard lock(client_error_mutex);
  if (!first_client_error) first_client_error = std::move(e);
}

// ---------------------------------------------------------------------------
// Submission
// ---------------------------------------------------------------------------
OpRecord* EngineState::make_insert(const Point3& p) {
  require_finite(p);
  require_inside(p, domain);
  sweep_tickets();
  OpRecord* op = records.acquire();
  try {
    const detail::TicketTable::Issued issued = tickets.issue(1);
    op->ticket = issued.first;
    op->ticket_range = issued.range;
    op->ticket_slot = issued.range->slot_of(issued.first);
  } catch (...) {
    records.release(op);
    throw;
  }
  op->kind = OpKind::insert;
  op->point = p;
  return op;
}

OpRecord* EngineState::make_remove(VertexHandle v) {
  auto dead = [&] {
    return Error(ErrorCode::unknown_vertex, "cannot remove vertex " + std::to_string(v.id) +
                                                ": it is not in the triangulation (never inserted, already removed" +
                                                (v.incarnation ? ", or that incarnation is gone)" : ")"));
  };
  if (v.id == 0) throw Error(ErrorCode::unknown_vertex, "cannot remove the infinite vertex (id 0)");
  if (v.id >= impl.verts.size()) throw dead();
  const std::uint64_t stamp = impl.verts[v.id].stamp.load(std::memory_order_acquire);
  if (stamp == 0 || (v.incarnation && v.incarnation != stamp)) throw dead();
  OpRecord* op = records.acquire();
  op->kind = OpKind::remove;
  op->vertex = v.id;
  op->stamp = v.incarnation ? v.incarnation : stamp;  // the incarnation seen now: a reuse of the id is not removed
  // Where it is: read under a shared lock if free; if a worker holds it right
  // now, the worker that pops the removal reads it.
  std::uint64_t now = 0;
  switch (read_vertex(impl, v.id, op->stamp, &op->point, &now)) {
    case VertexRead::read: return op;
    case VertexRead::held: op->routed = false; return op;  // the worker that pops it reads it
    case VertexRead::dead: break;
  }
  records.release(op);
  throw dead();
}

void EngineState::submit(OpRecord* op, std::uint32_t count) {
  // An operation whose place is unknown yet goes to a block picked by its
  // vertex id; the worker that pops it moves it on (engine_execute.cpp).
  // (An undo of a pending insertion has no vertex yet: its ticket spreads
  // such undos over the blocks instead of piling them into one.)
  const std::uint32_t b =
      op->routed ? partition.block_of(op->point)
                 : static_cast<std::uint32_t>((op->vertex != no_vertex ? op->vertex : op->ticket) % partition.blocks());
  Block& block = blocks[b];
  submitted[b % submit_shards].n.fetch_add(count, std::memory_order_relaxed);
  enqueue(block, op);
}

OpRecord* EngineState::make_undo(std::uint64_t t, const TicketView& view, Engine::Callback done,
                                 BatchCallback* batch_done) {
  OpRecord* op = records.acquire();
  op->kind = OpKind::remove_insertion;
  op->ticket = t;
  op->done = std::move(done);
  op->batch_done = batch_done;
  if (view.state == TicketState::inserted) {
    // Routed by its vertex (read like a removal's); if that is held right
    // now, the worker that pops it reads it.
    op->vertex = view.vertex;
    op->stamp = view.stamp;
  } else {
    // A pending insertion: any block will do (picked by the ticket), the
    // undo parks on its ticket and the insertion's completion routes it to
    // the vertex.
    op->vertex = no_vertex;
  }
  op->routed = false;
  return op;
}

}  // namespace detail

// ---------------------------------------------------------------------------
// Construction and destruction
// ---------------------------------------------------------------------------
Engine::Engine(Triangulation& t, const Box& domain, EngineOptions options, tbb::task_arena* arena) {
  auto bad = [](const std::string& what) { throw Error(ErrorCode::invalid_argument, what); };
  if (const char* why = detail::box_problem(domain))
    bad(std::string("the engine's domain box ") + why + "; it must be finite with lo <= hi on every axis");
  if (!(options.contention_low >= 0 && options.contention_low <= options.contention_high &&
        options.contention_high <= 1))
    bad("contention thresholds must satisfy 0 <= contention_low <= contention_high <= 1");
  const bool by_old_name = options.workers == 0 && options.threads != 0;
  if (options.workers == 0) options.workers = options.threads;  // the older name
  if (options.workers > EngineOptions::max_workers)
    bad(std::string(by_old_name ? "threads (the deprecated name of workers)" : "workers") + " must be at most " +
        std::to_string(EngineOptions::max_workers) + ", not " + std::to_string(options.workers));
  static_assert(EngineOptions::max_blocks_per_axis == detail::Partition::max_blocks_per_axis);
  if (options.blocks_per_axis > EngineOptions::max_blocks_per_axis)
    bad("blocks_per_axis must be at most " + std::to_string(EngineOptions::max_blocks_per_axis));
  if (options.contention_window == 0) options.contention_window = 1;
  tbb::task_arena attached(tbb::task_arena::attach{});
  tbb::task_arena* where = arena ? arena : &attached;
  if (!where->is_active()) where->initialize();
  const unsigned workers = options.workers ? options.workers : static_cast<unsigned>(std::max(1, where->max_concurrency()));
  unsigned blocks = options.blocks_per_axis;
  if (!blocks)  // EngineOptions::blocks_per_axis says why these numbers
    while (blocks < detail::Partition::max_blocks_per_axis && blocks * blocks * blocks < std::max(512u, 64 * workers))
      ++blocks;
  // One engine at a time: attach (a refusal changes nothing), then build.
  Triangulation::Impl& impl = detail::impl_of(t);
  if (impl.engine.load(std::memory_order_acquire) == nullptr && impl.seq->in_hook)
    bad("an Engine cannot be attached from the triangulation's own change hook, while the change it reports is "
        "being made; attach it after that call returns");
  const void* none = nullptr;
  if (!impl.engine.compare_exchange_strong(none, this))
    bad("another Engine is attached to this triangulation: one engine at a time may drive a triangulation; destroy "
        "the first before creating the next");
  try {
    state_ = std::make_unique<EngineState>(t, domain, options, workers, blocks, arena);
  } catch (...) {
    impl.engine.store(nullptr, std::memory_order_release);
    throw;
  }
}

Engine::~Engine() noexcept(false) {
  if (!state_) return;
  EngineState& e = *state_;
  if (EngineState::running_engine == &e) {
    // The destructor runs inside the engine's own work: the task running it
    // belongs to the engine, so the engine cannot be torn down under it.
    detail::keep_orphan(state_.release());
    throw Error(ErrorCode::invalid_argument,
                "an Engine was destroyed from one of its own callbacks, hooks or coroutines: it cannot destroy the "
                "work that runs it; destroy it from a thread outside the engine's work (the engine is left running "
                "and leaked)");
  }
  try {
    drain();
  } catch (...) {
    // A client error drain() would rethrow: nobody asked for it any more
    // (EngineStats::client_errors counted it).
  }
  Triangulation::Impl& impl = e.impl;
  state_.reset();
  impl.engine.store(nullptr, std::memory_order_release);
}

// ---------------------------------------------------------------------------
// Submission
// ---------------------------------------------------------------------------
namespace {

template <class Awaitable>
Awaitable request(Engine* engine, OpKind kind) {
  Awaitable a;
  a.engine = engine;
  a.request.kind = kind;
  return a;
}

}  // namespace

InsertAwaitable Engine::insert(const Point3& p) {
  auto a = request<InsertAwaitable>(this, OpKind::insert);
  a.request.point = p;
  return a;
}

InsertAwaitable Engine::insert_if_alive(const Point3& p, CellHandle h) {
  auto a = request<InsertAwaitable>(this, OpKind::insert);
  a.request.point = p;
  a.request.cell = h;
  a.request.only_if_alive = true;
  return a;
}

RemoveAwaitable Engine::remove(VertexId v) { return remove(VertexHandle{v, 0}); }

RemoveAwaitable Engine::remove(VertexHandle v) {
  auto a = request<RemoveAwaitable>(this, OpKind::remove);
  a.request.vertex = v;
  return a;
}

LocateAwaitable Engine::locate(const Point3& p) {
  auto a = request<LocateAwaitable>(this, OpKind::locate);
  a.request.point = p;
  return a;
}

NearestAwaitable Engine::nearest_vertex(const Point3& p) {
  auto a = request<NearestAwaitable>(this, OpKind::nearest_vertex);
  a.request.point = p;
  return a;
}

VisitAwaitable Engine::visit(CellHandle h, CellVisitor fn) {
  auto a = request<VisitAwaitable>(this, OpKind::visit);
  a.request.cell = h;
  a.request.visitor = std::move(fn);
  return a;
}

namespace detail {

// The record for a request of any kind but the ticket ones; throws pdt::Error
// for bad input, having submitted nothing.
OpRecord* make_record(EngineState& e, Request& q) {
  switch (q.kind) {
    case OpKind::insert: {
      if (!q.only_if_alive) return e.make_insert(q.point);
      require_finite(q.point);
      require_inside(q.point, e.domain);
      OpRecord* op = e.records.acquire();
      op->kind = OpKind::insert;
      op->point = q.point;
      op->cell = q.cell;
      op->only_if_alive = true;
      return op;
    }
    case OpKind::remove: return e.make_remove(q.vertex);
    case OpKind::locate:
    case OpKind::nearest_vertex: {
      require_finite(q.point);
      OpRecord* op = e.records.acquire();
      op->kind = q.kind;
      op->point = q.point;
      return op;
    }
    case OpKind::visit: {
      OpRecord* op = e.records.acquire();
      op->kind = OpKind::visit;
      op->cell = q.cell;
      op->vertex = q.cell.anchor;
      op->visitor = std::move(q.visitor);
      op->routed = false;  // where the anchor is: read by the worker that pops it
      if (q.cell.anchor == 0 || q.cell.anchor == no_vertex) op->routed = true;  // no anchor: dead at once
      return op;
    }
    case OpKind::remove_insertion: break;
  }
  throw Error(ErrorCode::invalid_argument, "this request has no awaitable form");
}

bool OpAwaitBase::await_suspend(std::coroutine_handle<> h) {
  waiter = h;
  if (!engine || awaited) {
    result.error = std::make_exception_ptr(
        Error(ErrorCode::invalid_argument,
              !engine ? "this engine awaitable holds no operation: it was moved from (await the one it was moved "
                        "to), or made without engine.insert() and the others"
                      : "this engine awaitable was awaited before; each is one operation, awaited once "
                        "(call engine.insert(), remove(), ... again for another)"));
    return false;  // await_resume throws it
  }
  awaited = true;
  EngineState& e = *engine->state_;
  OpRecord* op;
  try {
    op = make_record(e, request);
  } catch (...) {
    result.error = std::current_exception();
    return false;  // await_resume throws it
  }
  op->awaiter = this;
  e.submit(op);  // from here on `this` may already be resumed and gone
  return true;
}

}  // namespace detail

Engine::Ticket Engine::insert(const Point3& p, Callback done) {
  OpRecord* op = state_->make_insert(p);
  op->done = std::move(done);
  const Ticket t = op->ticket;
  state_->submit(op);
  return t;
}

void Engine::insert_if_alive(const Point3& p, CellHandle h, Callback done) {
  detail::Request q{OpKind::insert, p, {}, h, {}, true};
  OpRecord* op = detail::make_record(*state_, q);
  op->done = std::move(done);
  state_->submit(op);
}

void Engine::remove(VertexId v, Callback done) { remove(VertexHandle{v, 0}, std::move(done)); }

void Engine::remove(VertexHandle v, Callback done) {
  OpRecord* op = state_->make_remove(v);
  op->done = std::move(done);
  state_->submit(op);
}

void Engine::locate(const Point3& p, Callback done) {
  detail::Request q{OpKind::locate, p, {}, {}, {}, false};
  OpRecord* op = detail::make_record(*state_, q);
  op->done = std::move(done);
  state_->submit(op);
}

void Engine::nearest_vertex(const Point3& p, Callback done) {
  detail::Request q{OpKind::nearest_vertex, p, {}, {}, {}, false};
  OpRecord* op = detail::make_record(*state_, q);
  op->done = std::move(done);
  state_->submit(op);
}

void Engine::visit(CellHandle h, CellVisitor fn, Callback done) {
  detail::Request q{OpKind::visit, {}, {}, h, std::move(fn), false};
  OpRecord* op = detail::make_record(*state_, q);
  op->done = std::move(done);
  state_->submit(op);
}

Engine::Ticket Engine::insert_batch(std::span<const Point3> points, Callback done) {
  EngineState& e = *state_;
  // Checked on the caller's arena's threads; the point refused is the first
  // bad one in the caller's order, as a check in order would find.
  std::atomic<std::size_t> first_bad{points.size()};
  detail::for_range(points.size(), true, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end && k < first_bad.load(std::memory_order_relaxed); ++k)
      if (!detail::is_finite(points[k]) || !e.domain.contains(points[k])) {
        std::size_t seen = first_bad.load(std::memory_order_relaxed);
        while (k < seen && !first_bad.compare_exchange_weak(seen, k, std::memory_order_relaxed)) {
        }
        break;
      }
  });
  if (const std::size_t k = first_bad.load(); k < points.size()) {
    detail::require_finite(points[k]);
    detail::require_inside(points[k], e.domain);
  }
  if (points.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument,
                "insert_batch: " + std::to_string(points.size()) + " points; vertex ids allow at most 2^32 - 2");
  if (points.empty()) return e.tickets.issued();
  // Everything that may fail, before the first submission: the points in
  // insertion order, copied (the caller's span may go), cut into runs of
  // consecutive points in one block, one record each.
  auto shared = std::make_unique<detail::BatchCallback>();
  // In the caller's arena, not the engine's: entering a full arena waits for
  // its threads, which a hook may hold on a lock the caller has.
  shared->index = detail::spatial_order(points, true);
  shared->points = detail::make_raw_array<Point3>(points.size());  // first touched by the loop below
  const detail::RawArray<std::uint32_t> block_at =
      detail::make_raw_array<std::uint32_t>(points.size());  // the block of sorted point k
  detail::for_range(points.size(), true, [&, sorted = shared->points.get(), index = shared->index.data()](
                                               std::size_t begin, std::size_t end) {
    // Two loops: the gather alone keeps many of its cache misses in flight.
    for (std::size_t k = begin; k < end; ++k) sorted[k] = points[index[k]];
    std::uint32_t block = e.partition.blocks();  // no block yet: the piece's first point is searched for
    for (std::size_t k = begin; k < end; ++k) block_at[k] = block = e.partition.block_of(sorted[k], block);
  });
  shared->fn = std::move(done);
  shared->remaining.store(points.size());
  const std::size_t count = shared->point_count();
  const Point3* sorted = shared->points.get();
  std::vector<OpRecord*> runs;
  try {
    for (std::size_t k = 0; k < count;) {
      std::size_t end = k + 1;
      while (end < count && end - k < EngineState::max_run && block_at[end] == block_at[k]) ++end;
      runs.push_back(nullptr);
      OpRecord* op = runs.back() = e.records.acquire();
      op->kind = OpKind::insert;
      op->from_batch = true;
      op->point = sorted[k];
      op->run_next = static_cast<std::uint32_t>(k);
      op->run_end = static_cast<std::uint32_t>(end);
      k = end;
    }
    e.sweep_tickets();
    const detail::TicketTable::Issued issued = e.tickets.issue_ordered(shared->index);
    shared->first_ticket = issued.first;
    shared->ticket_range = issued.range;
  } catch (...) {
    for (OpRecord* op : runs)
      if (op) e.records.release(op);
    throw;
  }
  const Ticket first = shared->first_ticket;
  detail::BatchCallback* batch_done = shared.release();  // the last operation frees it
  for (OpRecord* op : runs) {
    op->batch_done = batch_done;
    e.submit(op, op->run_end - op->run_next);
  }
  return first;
}

InsertResult Engine::insertion_result(Ticket t) const { return state_->tickets.result(t, state_->impl.verts); }

void Engine::remove_insertion(Ticket t, Callback done) {
  const detail::TicketView view = state_->tickets.claim_undo(t, state_->impl.verts);
  try {
    state_->submit(state_->make_undo(t, view, std::move(done), nullptr));
  } catch (...) {
    state_->tickets.unclaim_undo(t);
    throw;
  }
}

void Engine::remove_insertions(std::span<const Ticket> batch, Callback done) {
  EngineState& e = *state_;
  if (batch.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument, "remove_insertions: " + std::to_string(batch.size()) + " tickets; at most 2^32 - 2");
  if (batch.empty()) return;
  // All or nothing: claim every ticket, and give the claims back on the first
  // bad one. A ticket given twice fails its second claim (its first made it
  // undone): named as what it is, found only then.
  std::vector<detail::TicketView> views(batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) {
    try {
      views[i] = e.tickets.claim_undo(batch[i], e.impl.verts);
    } catch (...) {
      for (std::size_t j = 0; j < i; ++j) e.tickets.unclaim_undo(batch[j]);
      const auto before = batch.begin() + static_cast<std::ptrdiff_t>(i);
      if (std::find(batch.begin(), before, batch[i]) != before)
        throw Error(ErrorCode::unknown_vertex, "remove_insertions: ticket " + std::to_string(batch[i]) +
                                                   " appears twice in the batch; each insertion is undone once");
      throw;
    }
  }
  // Everything that can fail (memory) before the first submission: on a
  // failure every claim is given back and nothing was submitted.
  std::vector<OpRecord*> ops;
  auto shared = std::make_unique<detail::BatchCallback>();
  try {
    // Spatial order, by the vertices' points where they can be read now.
    std::vector<Point3> where(batch.size());
    for (std::size_t i = 0; i < batch.size(); ++i) {
      std::uint64_t stamp = 0;
      if (views[i].state == detail::TicketState::inserted && views[i].vertex < e.impl.verts.size())
        detail::try_read_vertex(e.impl, views[i].vertex, views[i].stamp, &where[i], &stamp);
    }
    std::vector<std::uint32_t> order;
    order = detail::spatial_order(where, true);  // in the caller's arena (as insert_batch)
    ops.reserve(batch.size());
    for (std::uint32_t i : order) ops.push_back(e.make_undo(batch[i], views[i], {}, shared.get()));
    shared->fn = std::move(done);
  } catch (...) {
    for (OpRecord* op : ops) e.records.release(op);
    for (Ticket t : batch) e.tickets.unclaim_undo(t);
    throw;
  }
  shared->remaining.store(batch.size());
  shared.release();  // the last operation frees it
  for (OpRecord* op : ops) e.submit(op);
}

void Engine::set_change_hook(ChangeHook hook, bool report_destroyed) {
  EngineState& e = *state_;
  if (!e.idle_everywhere())
    throw Error(ErrorCode::invalid_argument,
                "Engine::set_change_hook while operations are in flight: set the hook before submitting, or after "
                "drain()");
  e.user_hook = std::move(hook);
  const ChangeHook* h = e.user_hook ? &e.kernel_hook : nullptr;
  for (auto& w : e.workers) {
    w->ctx->hook = h;
    w->ctx->report_destroyed = report_destroyed;
  }
  e.impl.seq->hook = h;
  e.impl.seq->report_destroyed = report_destroyed;
}

// ---------------------------------------------------------------------------
// Drain and statistics
// ---------------------------------------------------------------------------
void Engine::drain() {
  EngineState& e = *state_;
  if (EngineState::running_engine == &e)
    throw Error(ErrorCode::invalid_argument,
                "Engine::drain() was called from one of this engine's callbacks, hooks or coroutines; it would wait "
                "for itself. Call drain() from a thread outside the engine's work (or co_await each operation "
                "instead)");
  while (!e.idle_everywhere()) {
    e.arena->execute([&] { e.tasks.wait(); });
    if (!e.idle_everywhere()) {
      // Every task ended with work left: it sits with sleepers (or a
      // submitter is between its push and its wake-up). Wake someone.
      if (!e.wake_one() && !e.wake_idle()) std::this_thread::yield();
    }
  }
  e.arena->execute([&] { e.tasks.wait(); });  // continuations of awaiting coroutines
  std::exception_ptr first;
  {
    std::lock_guard lock(e.client_error_mutex);
    first.swap(e.first_client_error);
  }
  if (first) std::rethrow_exception(first);
}

std::uint64_t Engine::in_flight() const { return state_->in_flight(); }

EngineStats Engine::stats() const {
  const EngineState& e = *state_;
  EngineStats s;
  for (const auto& w : e.workers) {
    WorkerStats ws;
    ws.completed = w->completed.load();
    ws.attempts = w->attempts.load();
    ws.rollbacks = w->rollbacks.load();
    ws.deferred = w->deferred.load();
    ws.sleeps = w->sleeps.load();
    ws.steals = w->steals.load();
    ws.escalated = w->escalated.load();
    ws.seconds_asleep = w->seconds_asleep.load();
    // The start first: a stretch that ends meanwhile is in the sum then.
    const std::int64_t since = w->idle_since_ns.load(std::memory_order_acquire);
    ws.seconds_idle = w->seconds_idle.load(std::memory_order_acquire);
    if (since != 0) ws.seconds_idle += 1e-9 * double(std::max<std::int64_t>(0, detail::steady_ns() - since));
    ws.max_rollbacks_per_completed = ws.completed ? static_cast<double>(ws.rollbacks) / ws.completed : 0;
    s.workers.push_back(ws);
  }
  s.global_operations = e.global_ops.load();
  s.client_errors = e.client_errors.load();
  s.recuts = e.recuts.load();
  return s;
}

unsigned Engine::workers() const { return state_->nworkers; }
unsigned Engine::blocks_per_axis() const { return state_->partition.blocks_per_axis(); }
const EngineOptions& Engine::options() const { return state_->opts; }

}  // namespace pdt
