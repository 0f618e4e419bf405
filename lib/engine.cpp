// pdt::Engine: block-owned workers on oneTBB, try-locks with rollback, and
// the contention manager of Foteinos & Chrisochoides §3.
//
// Phases of a worker (a C++20 coroutine run as TBB tasks):
//   idle      its queue was empty; suspended. A submission to its queue
//             resumes it as a new task.
//   running   pops operations and runs them; a rollback re-queues the
//             operation at the back of its own queue.
//   sleeping  suspended by the contention manager (progress ratio below u-);
//             woken by a worker whose ratio is above u+, or by any worker
//             going idle, or by drain().
// Invariant: `active` counts running workers; a worker never goes to sleep
// when it is the last one running, so some worker always makes progress.
//
// Operations that change the dimension (the first points, a removal that
// leaves a coplanar set) cannot run under vertex locks: they run with the
// world stopped. The worker that needs it takes `global_mutex`, raises
// `world_stop` and waits until no other worker is inside an operation. The
// jump-and-walk grid is regrown the same way each time the vertex ids double,
// so it always holds about two vertices per slot (walks stay short at every
// size, and a small run does not pay for a domain-sized grid).
//
// Shared writes per operation are kept to the queue itself: counts of
// submitted and finished operations live on each worker (drain() sums them),
// and a worker folds its cell/vertex count deltas into the triangulation's
// totals only when it goes idle or to sleep.
#include "pdt/engine.hpp"

#include <oneapi/tbb/concurrent_vector.h>

#include <boost/lockfree/queue.hpp>
#include <boost/lockfree/stack.hpp>
#include <oneapi/tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <sstream>
#include <thread>

#include "pdt/error.hpp"
#include "spatial_order.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

namespace detail {

enum class OpKind : std::uint8_t { insert, remove, remove_insertion };

struct QueuedOp {
  OpKind kind = OpKind::insert;
  Point3 point;                 // insert: the point; removals: where the vertex is (routing)
  VertexId vertex = no_vertex;  // remove
  std::uint64_t stamp = 0;      // remove: the vertex incarnation expected (0 = any)
  std::uint64_t ticket = 0;     // insert: its own ticket; remove_insertion: the insertion undone
  bool from_batch = false;      // insert: part of a spatially sorted batch (walk from the last vertex)
  Engine::Callback done;
  OpAwaitBase* awaiter = nullptr;
};

struct TicketSlot {
  std::atomic<int> state{0};  // 0 pending, 1 inserted, 2 failed
  std::atomic<bool> undone{false};
  // An undo that found the insertion not done yet waits here (not in a queue,
  // where it would spin); the insertion's completion re-queues it. Dekker
  // handshake with `state`: each side stores its own word, then reads the
  // other's, all seq_cst, and `exchange` decides who re-queues.
  std::atomic<QueuedOp*> parked{nullptr};
  VertexId vertex = no_vertex;  // written before state becomes 1
  bool inserted = false;        // same
  std::exception_ptr error;     // written before state becomes 2
  std::uint64_t stamp = 0;
  Point3 point;
};

// A worker's body: a coroutine that never returns; destroyed while suspended.
struct WorkerCoroutine {
  struct promise_type {
    WorkerCoroutine get_return_object() {
      return {std::coroutine_handle<promise_type>::from_promise(*this)};
    }
    std::suspend_always initial_suspend() noexcept { return {}; }
    std::suspend_always final_suspend() noexcept { return {}; }
    void return_void() {}
    void unhandled_exception() { std::terminate(); }  // operations catch their own errors
  };
  std::coroutine_handle<promise_type> handle;
};

enum WorkerPhase : int { idle = 0, running = 1, sleeping = 2 };

struct alignas(64) Worker {
  unsigned index = 0;
  std::unique_ptr<OpContext> ctx;
  // Boost.Lockfree over oneTBB's concurrent_queue: 2x the throughput with one
  // producer and far better when threads outnumber cores (bench_queues).
  boost::lockfree::queue<QueuedOp*> queue{256};
  std::atomic<int> phase{idle};
  std::atomic<bool> in_op{false};
  std::coroutine_handle<> handle;
  // Contention manager window (owned by the worker's running task).
  std::uint32_t window_attempts = 0, window_completed = 0;
  std::chrono::steady_clock::time_point slept_at;
  // Statistics: written by the worker, read by stats() (relaxed).
  std::atomic<std::uint64_t> completed{0}, attempts{0}, rollbacks{0}, deferred{0}, sleeps{0};
  std::atomic<double> seconds_asleep{0};
  // Operations routed here, counted by submitters before the push (its own
  // cache line: submitters write it, the worker never does), and operations
  // finished, counted by the worker after their results are delivered.
  // finished <= submitted; drain() waits until they are equal for every worker.
  std::atomic<std::uint64_t> finished{0};
  alignas(64) std::atomic<std::uint64_t> submitted{0};
};

struct EngineState {
  EngineState(Triangulation& t, const Box& d, EngineOptions o, tbb::task_arena* a);

  Triangulation& tri;
  Triangulation::Impl& impl;
  Box domain;
  EngineOptions opts;
  tbb::task_arena attached;  // the caller's arena when none is passed
  tbb::task_arena* arena;
  tbb::task_group tasks;
  unsigned nthreads = 1, blocks = 1;
  std::vector<std::unique_ptr<Worker>> workers;
  std::vector<WorkerCoroutine> bodies;
  tbb::concurrent_vector<TicketSlot> tickets;
  std::mutex sleep_mutex;
  std::vector<Worker*> sleepers;
  std::atomic<int> active{0};
  std::mutex global_mutex;
  std::atomic<bool> world_stop{false};
  std::atomic<std::uint64_t> global_ops{0};
  // Vertex-id bound at which the jump grid is regrown (see the top comment).
  std::atomic<std::size_t> grid_grow_at{0};
  // Operation records: recycled through a lock-free free list, allocated in
  // slabs, so submitting allocates nothing once warm.
  boost::lockfree::stack<QueuedOp*> free_ops{1024};
  std::mutex slab_mutex;
  std::vector<std::unique_ptr<QueuedOp[]>> slabs;
  QueuedOp* acquire_op();
  void release_op(QueuedOp* op);

  // Runs h (a worker body or a coroutine awaiting a result) as a task of
  // `tasks`, marked as this engine's so drain() can refuse to wait for itself.
  void spawn(std::coroutine_handle<> h) {
    arena->execute([&] {
      tasks.run([this, h] {
        const EngineState* outer = running_engine;
        running_engine = this;
        h.resume();
        running_engine = outer;
      });
    });
  }
  // The engine whose task the current thread is running, if any.
  static thread_local const EngineState* running_engine;
  Worker& owner_of(const Point3& p);
  void submit(QueuedOp* op);
  void claim_undo(std::uint64_t t);  // marks insertion t undone; throws if it cannot be
  void submit_undo(std::uint64_t t, const Engine::Callback& done);
  void enqueue(Worker& w, QueuedOp* op);  // push and make sure w will run (op already counted)
  void resume(Worker& w);  // w was idle or asleep: mark it running and resume it as a task
  bool wake_one();
  void wake_locked(Worker& w);  // takes w off `sleepers` (caller holds sleep_mutex)
  QueuedOp* make_insert(const Point3& p);
  QueuedOp* make_remove(VertexId v);
  // Runs one operation's kernel call in ctx; the removal of a ticket uses the
  // vertex its insertion produced.
  OpStatus run_op(OpContext& ctx, QueuedOp& op, OpResult& r, std::uint64_t& stamp);
  void execute(Worker& w, QueuedOp* op);
  void run_global(Worker& w, QueuedOp* op);
  void complete(Worker& w, QueuedOp* op, OpResult& r, std::uint64_t stamp);
  void judge(Worker& w, bool* want_sleep);
  // World stop: true when w now runs alone (no other worker inside an
  // operation); false when another worker holds the world. w must not be
  // inside an operation itself.
  bool try_stop_world(Worker& w, std::unique_lock<std::mutex>& lock);
  void restart_world(std::unique_lock<std::mutex>& lock);
  void ensure_grid();  // with the world stopped (or before workers run)
  void maybe_grow_grid(Worker& w);
  bool idle_everywhere() const;  // no operation pending on any worker
  WorkerCoroutine body(Worker& w);
  void check_point(const Point3& p) const;
};

// -- awaiters of the worker coroutine ------------------------------------------
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
    wk->phase.store(idle, std::memory_order_seq_cst);
    es->active.fetch_sub(1, std::memory_order_seq_cst);
    es->wake_one();  // an idle worker competes with nobody: let a sleeper run
    if (!wk->queue.empty()) {
      int expect = idle;
      // Work arrived meanwhile and no submitter resumed us: resume as a new
      // task (not by returning false: a submitter may have resumed and
      // re-suspended this coroutine already, so only the handle is ours).
      if (wk->phase.compare_exchange_strong(expect, running)) es->resume(*wk);
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
    wk->phase.store(sleeping);
    es->active.fetch_sub(1);
    es->sleepers.push_back(wk);
    return true;
  }
  void await_resume() const noexcept {}
};

WorkerCoroutine EngineState::body(Worker& w) {
  for (;;) {
    QueuedOp* op = nullptr;
    while (w.queue.pop(op)) {
      execute(w, op);
      maybe_grow_grid(w);
      bool want_sleep = false;
      judge(w, &want_sleep);
      if (want_sleep) co_await SleepAwait{this, &w};
    }
    co_await IdleAwait{this, &w};
  }
}

EngineState::EngineState(Triangulation& t, const Box& d, EngineOptions o, tbb::task_arena* a)
    : tri(t), impl(t.impl()), domain(d), opts(o), attached(tbb::task_arena::attach{}), arena(a ? a : &attached) {
  if (!arena->is_active()) arena->initialize();
  nthreads = opts.threads ? opts.threads : static_cast<unsigned>(std::max(1, arena->max_concurrency()));
  blocks = opts.blocks_per_axis;
  if (!blocks)
    while (blocks * blocks * blocks < 4 * nthreads) ++blocks;
  for (unsigned i = 0; i < nthreads; ++i) {
    auto w = std::make_unique<Worker>();
    w->index = i;
    w->ctx = std::make_unique<OpContext>(i + 2, true);  // id 1 is the sequential context
    workers.push_back(std::move(w));
  }
  for (auto& w : workers) {
    bodies.push_back(body(*w));
    w->handle = bodies.back().handle;
  }
  ensure_grid();
}

void EngineState::ensure_grid() {
  if (impl.dim.load() < 3) return;  // no grid below dimension 3
  const std::size_t ids = impl.verts.size();
  if (impl.grid.slot_count && ids < grid_grow_at.load(std::memory_order_relaxed)) return;
  // Over the live vertices' bounding box, about two vertices per slot.
  impl.grid_rebuild(std::clamp<std::size_t>(ids / 2, 1, std::max<std::size_t>(opts.grid_slots, 1)));
  impl.grid.built_for = std::size_t{1} << 60;  // the kernel never rebuilds it while the engine runs
  grid_grow_at.store(2 * ids + 1024, std::memory_order_relaxed);
}

void EngineState::maybe_grow_grid(Worker& w) {
  // Below dimension 3 there is no grid; the global step that builds the
  // tetrahedra sizes it (run_global calls ensure_grid).
  if (impl.verts.size() < grid_grow_at.load(std::memory_order_relaxed) || impl.dim.load(std::memory_order_relaxed) < 3)
    return;
  std::unique_lock<std::mutex> lock;
  if (!try_stop_world(w, lock)) return;  // another worker is in a global step; it checks too
  ensure_grid();
  restart_world(lock);
}

bool EngineState::try_stop_world(Worker& w, std::unique_lock<std::mutex>& lock) {
  lock = std::unique_lock(global_mutex, std::try_to_lock);
  if (!lock.owns_lock()) return false;
  world_stop.store(true, std::memory_order_seq_cst);
  for (auto& other : workers)
    if (other.get() != &w)
      while (other->in_op.load(std::memory_order_seq_cst)) std::this_thread::yield();
  return true;
}

void EngineState::restart_world(std::unique_lock<std::mutex>& lock) {
  world_stop.store(false, std::memory_order_seq_cst);
  lock.unlock();
}

bool EngineState::idle_everywhere() const {
  // finished is read before submitted: equal values mean that at the moment
  // finished was read, everything submitted to the worker was done.
  for (const auto& w : workers) {
    const std::uint64_t f = w->finished.load(std::memory_order_acquire);
    if (f != w->submitted.load(std::memory_order_acquire)) return false;
  }
  return true;
}

Worker& EngineState::owner_of(const Point3& p) {
  const double c[3] = {p.x, p.y, p.z};
  const double lo[3] = {domain.lo.x, domain.lo.y, domain.lo.z};
  const double hi[3] = {domain.hi.x, domain.hi.y, domain.hi.z};
  std::size_t id = 0;
  for (int a = 2; a >= 0; --a) {
    double half_ext = 0.5 * hi[a] - 0.5 * lo[a];  // halves: no overflow
    double t = half_ext > 0 ? (0.5 * c[a] - 0.5 * lo[a]) / half_ext * blocks : 0.0;
    int b = t > 0 ? static_cast<int>(std::min(t, static_cast<double>(blocks - 1))) : 0;
    id = id * blocks + static_cast<std::size_t>(b);
  }
  // Contiguous runs of blocks per worker: each worker owns a compact region.
  std::size_t nblocks = std::size_t{blocks} * blocks * blocks;
  return *workers[id * nthreads / nblocks];
}

void EngineState::check_point(const Point3& p) const {
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
    std::ostringstream os;
    os.precision(17);
    os << "point (" << p.x << ", " << p.y << ", " << p.z
       << ") has a NaN or infinite coordinate; every coordinate must be a finite double";
    throw Error(ErrorCode::non_finite_coordinate, os.str());
  }
  if (!domain.contains(p)) {
    std::ostringstream os;
    os.precision(17);
    os << "point (" << p.x << ", " << p.y << ", " << p.z << ") is outside the engine's domain [" << domain.lo.x
       << ", " << domain.hi.x << "] x [" << domain.lo.y << ", " << domain.hi.y << "] x [" << domain.lo.z << ", "
       << domain.hi.z << "]; declare a box that holds every point the refiner may insert";
    throw Error(ErrorCode::outside_domain, os.str());
  }
}

void EngineState::resume(Worker& w) {
  active.fetch_add(1);
  spawn(w.handle);
}

QueuedOp* EngineState::make_insert(const Point3& p) {
  check_point(p);
  QueuedOp* op = acquire_op();
  op->kind = OpKind::insert;
  op->point = p;
  op->ticket = static_cast<std::uint64_t>(tickets.grow_by(1) - tickets.begin());
  tickets[op->ticket].point = p;
  return op;
}

QueuedOp* EngineState::make_remove(VertexId v) {
  if (v == 0 || v >= impl.verts.size())
    throw Error(ErrorCode::unknown_vertex, "cannot remove vertex " + std::to_string(v) + ": it is not in the triangulation");
  // The caller got v from a completed insertion it has not undone yet, so v
  // stays live, and its point and stamp fixed, until this removal runs: they
  // are read without a lock (the submitter is no worker and must not wait on
  // one). Read as a sequence lock, so a misused id (dead, or recycled right
  // now) gives stamp 0 or a changed stamp and a clean error, here or when the
  // removal runs and checks the incarnation under the vertex's lock.
  detail::VertexRec& rec = impl.verts[v];
  const std::uint64_t stamp = rec.stamp.load(std::memory_order_acquire);
  const Point3 where{rec.p.x(), rec.p.y(), rec.p.z()};
  std::atomic_thread_fence(std::memory_order_acquire);
  if (stamp == 0 || rec.stamp.load(std::memory_order_relaxed) != stamp)
    throw Error(ErrorCode::unknown_vertex, "cannot remove vertex " + std::to_string(v) + ": it is not in the triangulation");
  QueuedOp* op = acquire_op();
  op->kind = OpKind::remove;
  op->vertex = v;
  op->stamp = stamp;  // the incarnation seen now: a later reuse of the id is not removed
  op->point = where;
  return op;
}

QueuedOp* EngineState::acquire_op() {
  QueuedOp* op = nullptr;
  if (free_ops.pop(op)) return op;
  constexpr std::size_t slab = 4096;
  std::lock_guard lock(slab_mutex);
  slabs.push_back(std::make_unique<QueuedOp[]>(slab));
  QueuedOp* s = slabs.back().get();
  for (std::size_t i = 1; i < slab; ++i) free_ops.push(&s[i]);
  return &s[0];
}

void EngineState::release_op(QueuedOp* op) {
  op->done = nullptr;
  op->awaiter = nullptr;
  op->from_batch = false;
  free_ops.push(op);
}

void EngineState::submit(QueuedOp* op) {
  Worker& w = owner_of(op->point);
  w.submitted.fetch_add(1, std::memory_order_relaxed);
  enqueue(w, op);
}

void EngineState::enqueue(Worker& w, QueuedOp* op) {
  w.queue.push(op);
  int expect = idle;
  if (w.phase.compare_exchange_strong(expect, running)) {
    resume(w);
  } else if (expect == sleeping && active.load() == 0) {
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
  w.window_attempts = w.window_completed = 0;  // the manager is memoryless (§3.3)
  w.phase.store(running);
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

void EngineState::judge(Worker& w, bool* want_sleep) {
  if (w.window_attempts < opts.contention_window) return;
  double u = static_cast<double>(w.window_completed) / w.window_attempts;
  w.window_attempts = w.window_completed = 0;
  if (u < opts.contention_low)
    *want_sleep = true;
  else if (u > opts.contention_high)
    wake_one();
}

OpStatus EngineState::run_op(OpContext& ctx, QueuedOp& op, OpResult& r, std::uint64_t& stamp) {
  switch (op.kind) {
    case OpKind::insert: {
      const Point3& p = op.point;
      const VertexId hint = op.from_batch ? ctx.last_vertex : no_vertex;
      OpStatus s = impl.insert(ctx, KPoint(p.x + 0.0, p.y + 0.0, p.z + 0.0), hint, r.insert);
      if (s == OpStatus::done) stamp = ctx.result_stamp;
      return s;
    }
    case OpKind::remove:
      return impl.remove(ctx, op.vertex, op.stamp, r.remove);
    case OpKind::remove_insertion: {
      const TicketSlot& slot = tickets[op.ticket];
      if (slot.state.load(std::memory_order_acquire) == 2)
        throw Error(ErrorCode::unknown_vertex,
                    "cannot undo insertion " + std::to_string(op.ticket) + ": that insertion failed");
      return impl.remove(ctx, slot.vertex, slot.stamp, r.remove);
    }
  }
  return OpStatus::done;
}

void EngineState::execute(Worker& w, QueuedOp* opp) {
  QueuedOp& op = *opp;
  // Enter an operation unless the world is stopped (see run_global).
  w.in_op.store(true, std::memory_order_seq_cst);
  while (world_stop.load(std::memory_order_seq_cst)) {
    w.in_op.store(false, std::memory_order_seq_cst);
    while (world_stop.load(std::memory_order_acquire)) std::this_thread::yield();
    w.in_op.store(true, std::memory_order_seq_cst);
  }
  OpContext& ctx = *w.ctx;
  w.attempts.fetch_add(1, std::memory_order_relaxed);
  ++w.window_attempts;
  if (op.kind == OpKind::remove_insertion && tickets[op.ticket].state.load(std::memory_order_acquire) == 0) {
    // The insertion it undoes is not done yet: park it on the ticket.
    TicketSlot& slot = tickets[op.ticket];
    w.in_op.store(false, std::memory_order_release);
    w.deferred.fetch_add(1, std::memory_order_relaxed);
    slot.parked.store(opp, std::memory_order_seq_cst);
    if (slot.state.load(std::memory_order_seq_cst) != 0) {
      // Done meanwhile: take it back, unless the completion already did.
      if (QueuedOp* back = slot.parked.exchange(nullptr, std::memory_order_seq_cst)) w.queue.push(back);
    }
    return;
  }
  OpResult r;
  OpStatus s = OpStatus::done;
  std::uint64_t stamp = 0;
  try {
    s = run_op(ctx, op, r, stamp);
  } catch (...) {
    impl.release_all(ctx);
    r.error = std::current_exception();
    s = OpStatus::done;
  }
  w.in_op.store(false, std::memory_order_seq_cst);
  if (s == OpStatus::rollback) {
    w.rollbacks.fetch_add(1, std::memory_order_relaxed);
    w.queue.push(opp);
    return;
  }
  if (s == OpStatus::needs_global) {
    run_global(w, opp);
    return;
  }
  ++w.window_completed;
  complete(w, opp, r, stamp);
}

void EngineState::run_global(Worker& w, QueuedOp* opp) {
  QueuedOp& op = *opp;
  std::unique_lock<std::mutex> lock;
  if (!try_stop_world(w, lock)) {  // another worker is stopping the world: retry later
    w.rollbacks.fetch_add(1, std::memory_order_relaxed);
    w.queue.push(opp);
    return;
  }
  // Nobody else is inside an operation: run it single-threaded.
  OpContext& ctx = *impl.seq;
  OpResult r;
  std::uint64_t stamp = 0;
  try {
    run_op(ctx, op, r, stamp);  // single-threaded: always done
  } catch (...) {
    r.error = std::current_exception();
  }
  ensure_grid();
  global_ops.fetch_add(1, std::memory_order_relaxed);
  restart_world(lock);
  ++w.window_completed;
  complete(w, opp, r, stamp);
}

void EngineState::complete(Worker& w, QueuedOp* opp, OpResult& r, std::uint64_t stamp) {
  QueuedOp& op = *opp;
  if (op.kind != OpKind::remove) r.ticket = op.ticket;
  if (op.kind == OpKind::insert) {
    TicketSlot& slot = tickets[op.ticket];
    if (r.error) {
      slot.error = r.error;
      slot.state.store(2, std::memory_order_seq_cst);
    } else {
      slot.vertex = r.insert.vertex;
      slot.inserted = r.insert.inserted;
      slot.stamp = stamp;
      slot.state.store(1, std::memory_order_seq_cst);
    }
    if (QueuedOp* undo = slot.parked.exchange(nullptr, std::memory_order_seq_cst)) enqueue(owner_of(undo->point), undo);
  }
  w.completed.fetch_add(1, std::memory_order_relaxed);
  if (op.done) op.done(r);
  if (op.awaiter) {
    OpAwaitBase* a = op.awaiter;
    a->result = std::move(r);
    std::coroutine_handle<> h = a->waiter;  // `a` may be gone once h resumes
    spawn(h);
  }
  release_op(opp);
  w.finished.store(w.finished.load(std::memory_order_relaxed) + 1, std::memory_order_release);
}

thread_local const EngineState* EngineState::running_engine = nullptr;

}  // namespace detail

using detail::EngineState;
using detail::OpKind;
using detail::QueuedOp;

// ---------------------------------------------------------------------------
// Options
// ---------------------------------------------------------------------------
namespace {

template <class T>
void env_number(const char* name, T& field) {
  const char* s = std::getenv(name);
  if (!s || !*s) return;
  char* end = nullptr;
  double v = std::strtod(s, &end);
  bool ok = end && *end == '\0' && std::isfinite(v) && v >= 0;
  if constexpr (std::is_integral_v<T>) ok = ok && v == std::floor(v) && v <= 1e12;
  if (!ok)
    throw Error(ErrorCode::invalid_argument,
                std::string(name) + "='" + s + "' is not a valid value (expected a non-negative number)");
  field = static_cast<T>(v);
}

}  // namespace

EngineOptions EngineOptions::from_environment(EngineOptions o) {
  env_number("PDT_THREADS", o.threads);
  env_number("PDT_BLOCKS_PER_AXIS", o.blocks_per_axis);
  env_number("PDT_CONTENTION_LOW", o.contention_low);
  env_number("PDT_CONTENTION_HIGH", o.contention_high);
  env_number("PDT_CONTENTION_WINDOW", o.contention_window);
  env_number("PDT_GRID_SLOTS", o.grid_slots);
  return o;
}

EngineOptions EngineOptions::from_environment() { return from_environment(EngineOptions{}); }

const char* allocator_name() {
#ifdef PDT_USE_MIMALLOC
  return "mimalloc";
#else
  return "pool";
#endif
}

WorkerStats EngineStats::total() const {
  WorkerStats t;
  for (const WorkerStats& w : workers) {
    t.completed += w.completed;
    t.attempts += w.attempts;
    t.rollbacks += w.rollbacks;
    t.deferred += w.deferred;
    t.sleeps += w.sleeps;
    t.seconds_asleep += w.seconds_asleep;
    t.max_rollbacks_per_completed = std::max(t.max_rollbacks_per_completed, w.max_rollbacks_per_completed);
  }
  return t;
}

// ---------------------------------------------------------------------------
// Engine
// ---------------------------------------------------------------------------
Engine::Engine(Triangulation& t, const Box& domain, EngineOptions options, tbb::task_arena* arena) {
  auto bad = [](const std::string& what) { throw Error(ErrorCode::invalid_argument, what); };
  const double corners[6] = {domain.lo.x, domain.lo.y, domain.lo.z, domain.hi.x, domain.hi.y, domain.hi.z};
  // Each coordinate on its own: a sum would overflow for a box near +-DBL_MAX.
  if (!(domain.lo.x <= domain.hi.x && domain.lo.y <= domain.hi.y && domain.lo.z <= domain.hi.z) ||
      !std::all_of(std::begin(corners), std::end(corners), [](double c) { return std::isfinite(c); }))
    bad("the engine's domain box must be finite with lo <= hi on every axis");
  if (!(options.contention_low >= 0 && options.contention_low <= options.contention_high &&
        options.contention_high <= 1))
    bad("contention thresholds must satisfy 0 <= contention_low <= contention_high <= 1");
  if (options.threads > 4096) bad("threads must be at most 4096");
  if (options.blocks_per_axis > 1024) bad("blocks_per_axis must be at most 1024");
  if (options.contention_window == 0) options.contention_window = 1;
  state_ = std::make_unique<EngineState>(t, domain, options, arena);
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
    TriangulationStats& into = impl.seq->stats;
    const TriangulationStats& from = w->ctx->stats;
    into.insertions += from.insertions;
    into.duplicates += from.duplicates;
    into.removals += from.removals;
    into.cells_created_by_insert += from.cells_created_by_insert;
    into.cells_created_by_remove += from.cells_created_by_remove;
    into.cells_touched_by_remove += from.cells_touched_by_remove;
    into.walk_steps += from.walk_steps;
  }
  impl.grid.built_for = static_cast<std::size_t>(impl.n_vertices.load());
}

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
  QueuedOp* op;
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
  QueuedOp* op;
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
  QueuedOp* op = state_->make_insert(p);
  op->done = std::move(done);
  Ticket t = op->ticket;
  state_->submit(op);
  return t;
}

void Engine::remove(VertexId v, Callback done) {
  QueuedOp* op = state_->make_remove(v);
  op->done = std::move(done);
  state_->submit(op);
}

Engine::Ticket Engine::insert_batch(std::span<const Point3> points, Callback done) {
  EngineState& e = *state_;
  for (const Point3& p : points) e.check_point(p);
  if (points.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument,
                "insert_batch: " + std::to_string(points.size()) + " points; vertex ids allow at most 2^32 - 2");
  std::vector<std::uint32_t> order;
  e.arena->execute([&] { order = detail::spatial_order(points, true); });
  const auto first = static_cast<Ticket>(e.tickets.grow_by(points.size()) - e.tickets.begin());
  for (std::size_t i = 0; i < points.size(); ++i) e.tickets[first + i].point = points[i];
  for (std::uint32_t i : order) {
    QueuedOp* op = e.acquire_op();
    op->kind = OpKind::insert;
    op->point = points[i];
    op->ticket = first + i;
    op->from_batch = true;
    op->done = done;
    e.submit(op);
  }
  return first;
}

InsertResult Engine::insertion_result(Ticket t) const {
  const EngineState& e = *state_;
  if (t >= e.tickets.size())
    throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) + " was never submitted");
  const detail::TicketSlot& slot = e.tickets[t];
  switch (slot.state.load(std::memory_order_acquire)) {
    case 1: return {slot.vertex, slot.inserted};
    case 2: std::rethrow_exception(slot.error);
    default:
      throw Error(ErrorCode::invalid_argument,
                  "insertion " + std::to_string(t) + " has not finished; drain() first, or wait for its callback");
  }
}

void EngineState::claim_undo(std::uint64_t t) {
  if (t >= tickets.size())
    throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": no such insertion was submitted");
  if (tickets[t].undone.exchange(true))
    throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": it was already undone");
}

void EngineState::submit_undo(std::uint64_t t, const Engine::Callback& done) {
  QueuedOp& op = *acquire_op();
  op.kind = OpKind::remove_insertion;
  op.ticket = t;
  op.point = tickets[t].point;
  op.done = done;
  submit(&op);
}

void Engine::remove_insertion(Ticket t, Callback done) {
  state_->claim_undo(t);
  state_->submit_undo(t, done);
}

void Engine::remove_insertions(std::span<const Ticket> batch, Callback done) {
  EngineState& e = *state_;
  if (batch.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument, "remove_insertions: " + std::to_string(batch.size()) + " tickets; at most 2^32 - 2");
  // All or nothing: claim every ticket, and give the claims back on the first bad one.
  for (std::size_t i = 0; i < batch.size(); ++i) {
    try {
      e.claim_undo(batch[i]);
    } catch (...) {
      for (std::size_t j = 0; j < i; ++j) e.tickets[batch[j]].undone.store(false);
      throw;
    }
  }
  std::vector<Point3> where(batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) where[i] = e.tickets[batch[i]].point;
  std::vector<std::uint32_t> order;
  e.arena->execute([&] { order = detail::spatial_order(where, true); });
  for (std::uint32_t i : order) e.submit_undo(batch[i], done);
}

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

unsigned Engine::threads() const { return state_->nthreads; }
unsigned Engine::blocks_per_axis() const { return state_->blocks; }
const EngineOptions& Engine::options() const { return state_->opts; }

}  // namespace pdt
