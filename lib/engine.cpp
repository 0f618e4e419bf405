// pdt::Engine's public API: construction, submission, drain, statistics.
// The workers themselves are in engine_workers.cpp; the rooms are listed in
// engine_state.hpp.
#include "pdt/engine.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include "engine_state.hpp"
#include "pdt/error.hpp"
#include "point_checks.hpp"
#include "spatial_order.hpp"

namespace pdt {

using detail::EngineState;
using detail::OpRecord;

namespace detail {

EngineState::EngineState(Triangulation& t, const Box& d, EngineOptions o, unsigned nw, unsigned blocks,
                         tbb::task_arena* a)
    : impl(impl_of(t)),
      domain(d),
      opts(o),
      attached(tbb::task_arena::attach{}),
      arena(a ? a : &attached),
      nworkers(nw),
      partition(d, blocks, nw),
      world(nw) {
  for (unsigned i = 0; i < nworkers; ++i)
    workers.push_back(std::make_unique<Worker>(i, i + 2, opts));  // context id 1 is the sequential one
  for (auto& w : workers) {
    bodies.push_back(body(*w));
    w->handle = bodies.back().handle;
  }
  impl.grid_growth = Triangulation::Impl::GridGrowth::engine;
  ensure_grid();
}

OpRecord* EngineState::make_insert(const Point3& p) {
  require_finite(p);
  require_inside(p, domain);
  OpRecord* op = records.acquire();
  op->kind = OpKind::insert;
  op->point = p;
  op->ticket = tickets.issue(std::span<const Point3>(&p, 1));
  return op;
}

OpRecord* EngineState::make_remove(VertexId v) {
  if (v == 0 || v >= impl.verts.size())
    throw Error(ErrorCode::unknown_vertex, "cannot remove vertex " + std::to_string(v) + ": it is not in the triangulation");
  // The caller got v from a completed insertion it has not undone yet, so v
  // stays live, and its point and stamp fixed, until this removal runs: they
  // are read without a lock (the submitter is no worker and must not wait on
  // one). Read as a sequence lock, so a misused id (dead, or recycled right
  // now) gives stamp 0 or a changed stamp and a clean error, here or when the
  // removal runs and checks the incarnation under the vertex's lock.
  VertexRec& rec = impl.verts[v];
  const std::uint64_t stamp = rec.stamp.load(std::memory_order_acquire);
  const Point3 where{rec.p.x(), rec.p.y(), rec.p.z()};
  std::atomic_thread_fence(std::memory_order_acquire);
  if (stamp == 0 || rec.stamp.load(std::memory_order_relaxed) != stamp)
    throw Error(ErrorCode::unknown_vertex, "cannot remove vertex " + std::to_string(v) + ": it is not in the triangulation");
  OpRecord* op = records.acquire();
  op->kind = OpKind::remove;
  op->vertex = v;
  op->stamp = stamp;  // the incarnation seen now: a later reuse of the id is not removed
  op->point = where;
  return op;
}

void EngineState::submit(OpRecord* op) {
  Worker& w = *workers[partition.worker_of(op->point)];
  w.submitted.fetch_add(1, std::memory_order_relaxed);
  enqueue(w, op);
}

void EngineState::submit_undo(std::uint64_t t, const Engine::Callback& done) {
  OpRecord& op = *records.acquire();
  op.kind = OpKind::remove_insertion;
  op.ticket = t;
  op.point = tickets[t].point;
  op.done = done;
  submit(&op);
}

}  // namespace detail

// ---------------------------------------------------------------------------
// Construction
// ---------------------------------------------------------------------------
Engine::Engine(Triangulation& t, const Box& domain, EngineOptions options, tbb::task_arena* arena) {
  auto bad = [](const std::string& what) { throw Error(ErrorCode::invalid_argument, what); };
  if (detail::box_problem(domain)) bad("the engine's domain box must be finite with lo <= hi on every axis");
  if (!(options.contention_low >= 0 && options.contention_low <= options.contention_high &&
        options.contention_high <= 1))
    bad("contention thresholds must satisfy 0 <= contention_low <= contention_high <= 1");
  if (options.workers == 0) options.workers = options.threads;  // the 0.1 name
  if (options.workers > 4096) bad("workers must be at most 4096");
  if (options.blocks_per_axis > 1024) bad("blocks_per_axis must be at most 1024");
  if (options.contention_window == 0) options.contention_window = 1;
  tbb::task_arena attached(tbb::task_arena::attach{});
  tbb::task_arena* where = arena ? arena : &attached;
  if (!where->is_active()) where->initialize();
  const unsigned workers = options.workers ? options.workers : static_cast<unsigned>(std::max(1, where->max_concurrency()));
  unsigned blocks = options.blocks_per_axis;
  if (!blocks)
    while (blocks * blocks * blocks < 4 * workers) ++blocks;
  state_ = std::make_unique<EngineState>(t, domain, options, workers, blocks, arena);
}

Engine::~Engine() {
  if (!state_) return;
  drain();
  EngineState& e = *state_;
  for (auto& b : e.bodies) b.handle.destroy();
  // Give the workers' pools and statistics back to the triangulation.
  Triangulation::Impl& impl = e.impl;
  for (auto& w : e.workers) {
    impl.merge_pools(*impl.seq, *w->ctx);
    impl.seq->stats += w->ctx->stats;
  }
  impl.grid_growth = Triangulation::Impl::GridGrowth::kernel;
}

// ---------------------------------------------------------------------------
// Submission
// ---------------------------------------------------------------------------
InsertAwaitable Engine::insert(const Point3& p) {
  InsertAwaitable a;
  a.engine = this;
  a.point_ = p;
  return a;
}

RemoveAwaitable Engine::remove(VertexId v) {
  RemoveAwaitable a;
  a.engine = this;
  a.vertex_ = v;
  return a;
}

bool InsertAwaitable::await_suspend(std::coroutine_handle<> h) {
  waiter = h;
  EngineState& e = *engine->state_;
  OpRecord* op;
  try {
    op = e.make_insert(point_);
  } catch (...) {
    result.error = std::current_exception();
    return false;  // await_resume throws it
  }
  op->awaiter = this;
  e.submit(op);  // from here on `this` may already be resumed and gone
  return true;
}

InsertResult InsertAwaitable::await_resume() {
  if (result.error) std::rethrow_exception(result.error);
  return result.insert;
}

bool RemoveAwaitable::await_suspend(std::coroutine_handle<> h) {
  waiter = h;
  EngineState& e = *engine->state_;
  OpRecord* op;
  try {
    op = e.make_remove(vertex_);
  } catch (...) {
    result.error = std::current_exception();
    return false;
  }
  op->awaiter = this;
  e.submit(op);
  return true;
}

RemoveResult RemoveAwaitable::await_resume() {
  if (result.error) std::rethrow_exception(result.error);
  return result.remove;
}

Engine::Ticket Engine::insert(const Point3& p, Callback done) {
  OpRecord* op = state_->make_insert(p);
  op->done = std::move(done);
  Ticket t = op->ticket;
  state_->submit(op);
  return t;
}

void Engine::remove(VertexId v, Callback done) {
  OpRecord* op = state_->make_remove(v);
  op->done = std::move(done);
  state_->submit(op);
}

Engine::Ticket Engine::insert_batch(std::span<const Point3> points, Callback done) {
  EngineState& e = *state_;
  for (const Point3& p : points) {
    detail::require_finite(p);
    detail::require_inside(p, e.domain);
  }
  if (points.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument,
                "insert_batch: " + std::to_string(points.size()) + " points; vertex ids allow at most 2^32 - 2");
  std::vector<std::uint32_t> order;
  e.arena->execute([&] { order = detail::spatial_order(points, true); });
  const Ticket first = e.tickets.issue(points);
  for (std::uint32_t i : order) {
    OpRecord* op = e.records.acquire();
    op->kind = OpKind::insert;
    op->point = points[i];
    op->ticket = first + i;
    op->from_batch = true;
    op->done = done;
    e.submit(op);
  }
  return first;
}

InsertResult Engine::insertion_result(Ticket t) const { return state_->tickets.result(t); }

void Engine::remove_insertion(Ticket t, Callback done) {
  state_->tickets.claim_undo(t);
  state_->submit_undo(t, done);
}

void Engine::remove_insertions(std::span<const Ticket> batch, Callback done) {
  EngineState& e = *state_;
  if (batch.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument, "remove_insertions: " + std::to_string(batch.size()) + " tickets; at most 2^32 - 2");
  // All or nothing: claim every ticket, and give the claims back on the first bad one.
  for (std::size_t i = 0; i < batch.size(); ++i) {
    try {
      e.tickets.claim_undo(batch[i]);
    } catch (...) {
      for (std::size_t j = 0; j < i; ++j) e.tickets.unclaim_undo(batch[j]);
      throw;
    }
  }
  std::vector<Point3> where(batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) where[i] = e.tickets[batch[i]].point;
  std::vector<std::uint32_t> order;
  e.arena->execute([&] { order = detail::spatial_order(where, true); });
  for (std::uint32_t i : order) e.submit_undo(batch[i], done);
}

// ---------------------------------------------------------------------------
// Drain and statistics
// ---------------------------------------------------------------------------
void Engine::drain() {
  EngineState& e = *state_;
  if (EngineState::running_engine == &e)
    throw Error(ErrorCode::invalid_argument,
                "Engine::drain() was called from one of this engine's callbacks or from a coroutine resumed by "
                "it; it would wait for itself. Call drain() from a thread outside the engine's work (or co_await "
                "each operation instead)");
  while (!e.idle_everywhere()) {
    e.arena->execute([&] { e.tasks.wait(); });
    if (!e.idle_everywhere()) {
      // Every task ended with work left: it sits with sleepers. Wake them.
      if (!e.wake_one()) std::this_thread::yield();
    }
  }
  e.arena->execute([&] { e.tasks.wait(); });  // continuations of awaiting coroutines
}

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
    ws.seconds_asleep = w->seconds_asleep.load();
    ws.max_rollbacks_per_completed = ws.completed ? static_cast<double>(ws.rollbacks) / ws.completed : 0;
    s.workers.push_back(ws);
  }
  s.global_operations = e.global_ops.load();
  return s;
}

unsigned Engine::workers() const { return state_->nworkers; }
unsigned Engine::blocks_per_axis() const { return state_->partition.blocks_per_axis(); }
const EngineOptions& Engine::options() const { return state_->opts; }

}  // namespace pdt
