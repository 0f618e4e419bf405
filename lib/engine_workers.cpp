// The engine's workers (paper §3): coroutine bodies run as oneTBB tasks, their
// phases and wake-ups, and running and completing one operation.
#include <algorithm>
#include <cassert>

#include "engine_state.hpp"
#include "pdt/error.hpp"

namespace pdt::detail {

thread_local const EngineState* EngineState::running_engine = nullptr;

void EngineState::spawn(std::coroutine_handle<> h) {
  arena->execute([&] {
    tasks.run([this, h] {
      const EngineState* outer = running_engine;
      running_engine = this;
      h.resume();
      running_engine = outer;
    });
  });
}

// ---------------------------------------------------------------------------
// Phases: the awaiters that suspend a worker, and waking one
// ---------------------------------------------------------------------------
namespace {

struct IdleAwait {
  EngineState* e;
  Worker* w;
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h) {
    // Once `phase` says idle, a submitter may resume us on another thread:
    // from then on touch only locals (not this awaiter, which lives in the frame).
    EngineState* es = e;
    Worker* wk = w;
    es->impl.fold_counters(*wk->ctx);
    wk->handle = h;
    wk->phase.store(WorkerPhase::idle, std::memory_order_seq_cst);
    es->active.fetch_sub(1, std::memory_order_seq_cst);
    es->wake_one();  // an idle worker competes with nobody: let a sleeper run
    if (!wk->queue.empty()) {
      WorkerPhase expect = WorkerPhase::idle;
      // Work arrived meanwhile and no submitter resumed us: resume as a new
      // task (not by returning false: a submitter may have resumed and
      // re-suspended this coroutine already, so only the handle is ours).
      if (wk->phase.compare_exchange_strong(expect, WorkerPhase::running)) es->resume(*wk);
    }
    return true;
  }
  void await_resume() const noexcept {}
};

struct SleepAwait {
  EngineState* e;
  Worker* w;
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h) {
    EngineState* es = e;
    Worker* wk = w;
    es->impl.fold_counters(*wk->ctx);
    std::lock_guard lock(es->sleep_mutex);
    if (es->active.load() <= 1) return false;  // the last running worker never sleeps
    wk->handle = h;
    wk->slept_at = std::chrono::steady_clock::now();
    wk->sleeps.fetch_add(1, std::memory_order_relaxed);
    wk->phase.store(WorkerPhase::sleeping);
    es->active.fetch_sub(1);
    es->sleepers.push_back(wk);
    return true;
  }
  void await_resume() const noexcept {}
};

}  // namespace

WorkerCoroutine EngineState::body(Worker& w) {
  for (;;) {
    OpRecord* op = nullptr;
    while (w.queue.pop(op)) {
      execute(w, op);
      maybe_grow_grid(w);
      using Verdict = ContentionManager::Verdict;
      switch (w.contention.judge()) {
        case Verdict::sleep: co_await SleepAwait{this, &w}; break;
        case Verdict::wake_another: wake_one(); break;
        case Verdict::carry_on: break;
      }
    }
    co_await IdleAwait{this, &w};
  }
}

void EngineState::resume(Worker& w) {
  active.fetch_add(1);
  spawn(w.handle);
}

void EngineState::enqueue(Worker& w, OpRecord* op) {
  w.queue.push(op);
  WorkerPhase expect = WorkerPhase::idle;
  if (w.phase.compare_exchange_strong(expect, WorkerPhase::running)) {
    resume(w);
  } else if (expect == WorkerPhase::sleeping && active.load() == 0) {
    // Nobody runs to wake it: do it here.
    std::unique_lock lock(sleep_mutex);
    if (std::find(sleepers.begin(), sleepers.end(), &w) == sleepers.end()) return;
    wake_locked(w);
    lock.unlock();
    resume(w);
  }
}

void EngineState::wake_locked(Worker& w) {
  sleepers.erase(std::find(sleepers.begin(), sleepers.end(), &w));
  w.seconds_asleep.store(w.seconds_asleep.load() +
                         std::chrono::duration<double>(std::chrono::steady_clock::now() - w.slept_at).count());
  w.contention.forget();  // the manager is memoryless (§3.3)
  w.phase.store(WorkerPhase::running);
}

bool EngineState::wake_one() {
  Worker* w = nullptr;
  {
    std::lock_guard lock(sleep_mutex);
    if (sleepers.empty()) return false;
    w = sleepers.back();
    wake_locked(*w);
  }
  resume(*w);
  return true;
}

bool EngineState::idle_everywhere() const {
  // finished is read before submitted: equal values mean that at the moment
  // finished was read, everything submitted to the worker was done.
  for (const auto& w : workers) {
    const std::uint64_t f = w->finished.load(std::memory_order_acquire);
    const std::uint64_t s = w->submitted.load(std::memory_order_acquire);
    assert(f <= s);
    if (f != s) return false;
  }
  return true;
}

// ---------------------------------------------------------------------------
// The jump grid's growth, with the world stopped
// ---------------------------------------------------------------------------
void EngineState::ensure_grid() {
  if (impl.dim.load() < 3) return;  // no grid below dimension 3
  const std::size_t ids = impl.verts.size();
  if (impl.grid.slot_count && ids < grid_grow_at.load(std::memory_order_relaxed)) return;
  // Over the live vertices' bounding box, about two vertices per slot.
  impl.grid_rebuild(std::clamp<std::size_t>(ids / 2, 1, std::max<std::size_t>(opts.grid_slots, 1)));
  grid_grow_at.store(2 * ids + 1024, std::memory_order_relaxed);
}

void EngineState::maybe_grow_grid(Worker& w) {
  // Below dimension 3 there is no grid; the global step that builds the
  // tetrahedra sizes it (run_global calls ensure_grid).
  if (impl.verts.size() < grid_grow_at.load(std::memory_order_relaxed) || impl.dim.load(std::memory_order_relaxed) < 3)
    return;
  std::unique_lock<std::mutex> lock;
  if (!world.try_stop(w.index, lock)) return;  // another worker is in a global step; it checks too
  ensure_grid();
  world.restart(lock);
}

// ---------------------------------------------------------------------------
// Running one operation
// ---------------------------------------------------------------------------
OpStatus EngineState::run_op(Worker& w, OpContext& ctx, OpRecord& op, OpResult& r, std::uint64_t& stamp) {
  switch (op.kind) {
    case OpKind::insert: {
      const VertexId hint = op.from_batch ? w.last_inserted : no_vertex;
      Triangulation::Impl::Inserted out;
      OpStatus s = impl.insert(ctx, to_kpoint(op.point), hint, out);
      if (s == OpStatus::done) {
        r.insert = out.result;
        stamp = out.stamp;
        w.last_inserted = out.result.vertex;
      }
      return s;
    }
    case OpKind::remove:
      return impl.remove(ctx, op.vertex, op.stamp, r.remove);
    case OpKind::remove_insertion: {
      const TicketSlot& slot = tickets[op.ticket];
      if (slot.state.load(std::memory_order_acquire) == TicketState::failed)
        throw Error(ErrorCode::unknown_vertex,
                    "cannot undo insertion " + std::to_string(op.ticket) + ": that insertion failed");
      return impl.remove(ctx, slot.vertex, slot.stamp, r.remove);
    }
  }
  return OpStatus::done;
}

void EngineState::execute(Worker& w, OpRecord* opp) {
  OpRecord& op = *opp;
  world.enter(w.index);  // unless the world is stopped (see run_global)
  OpContext& ctx = *w.ctx;
  w.attempts.fetch_add(1, std::memory_order_relaxed);
  w.contention.attempted();
  if (op.kind == OpKind::remove_insertion &&
      tickets[op.ticket].state.load(std::memory_order_acquire) == TicketState::pending) {
    // The insertion it undoes is not done yet: park it on the ticket.
    world.leave(w.index);
    w.deferred.fetch_add(1, std::memory_order_relaxed);
    if (OpRecord* back = tickets.park(op.ticket, opp)) w.queue.push(back);
    return;
  }
  OpResult r;
  OpStatus s = OpStatus::done;
  std::uint64_t stamp = 0;
  try {
    s = run_op(w, ctx, op, r, stamp);
  } catch (...) {
    impl.release_all(ctx);
    r.error = std::current_exception();
    s = OpStatus::done;
  }
  world.leave(w.index);
  if (s == OpStatus::rollback) {
    w.rollbacks.fetch_add(1, std::memory_order_relaxed);
    w.queue.push(opp);
    return;
  }
  if (s == OpStatus::needs_global) {
    run_global(w, opp);
    return;
  }
  w.contention.completed();
  complete(w, opp, r, stamp);
}

void EngineState::run_global(Worker& w, OpRecord* opp) {
  OpRecord& op = *opp;
  std::unique_lock<std::mutex> lock;
  if (!world.try_stop(w.index, lock)) {  // another worker is stopping the world: retry later
    w.rollbacks.fetch_add(1, std::memory_order_relaxed);
    w.queue.push(opp);
    return;
  }
  // Nobody else is inside an operation: run it single-threaded.
  OpContext& ctx = *impl.seq;
  OpResult r;
  std::uint64_t stamp = 0;
  try {
    run_op(w, ctx, op, r, stamp);  // single-threaded: always done
  } catch (...) {
    r.error = std::current_exception();
  }
  ensure_grid();
  global_ops.fetch_add(1, std::memory_order_relaxed);
  world.restart(lock);
  w.contention.completed();
  complete(w, opp, r, stamp);
}

void EngineState::complete(Worker& w, OpRecord* opp, OpResult& r, std::uint64_t stamp) {
  OpRecord& op = *opp;
  r.kind = op.kind;
  if (op.kind != OpKind::remove) r.ticket = op.ticket;
  if (op.kind == OpKind::insert) {
    OpRecord* undo = r.error ? tickets.finish_failed(op.ticket, r.error) : tickets.finish_inserted(op.ticket, r.insert, stamp);
    if (undo) enqueue(*workers[partition.worker_of(undo->point)], undo);
  }
  w.completed.fetch_add(1, std::memory_order_relaxed);
  if (op.done) op.done(r);
  if (op.awaiter) {
    OpAwaitBase* a = op.awaiter;
    a->result = std::move(r);
    std::coroutine_handle<> h = a->waiter;  // `a` may be gone once h resumes
    spawn(h);
  }
  records.release(opp);
  assert(w.finished.load(std::memory_order_relaxed) < w.submitted.load(std::memory_order_relaxed));
  w.finished.store(w.finished.load(std::memory_order_relaxed) + 1, std::memory_order_release);
}

}  // namespace pdt::detail
