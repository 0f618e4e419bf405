// SPDX-License-Identifier: MIT
#pragma once
// The engine's state, by room:
//   partition.hpp          blocks of the domain along a Morton curve, homes
//   block_queue.hpp        the operations waiting in one block
//   op_record.hpp          submitted operations and their pool
//   tickets.hpp            insertions by ticket, and undos waiting for them
//   contention_manager.hpp the progress ratio and its verdicts
//   stopped_world.hpp      running alone (dimension changes, escalations, grid growth,
//                          recuts)
//   engine_scheduler.cpp   the workers: coroutine bodies, claiming blocks
//                          (home first, then stealing), phases and wake-ups
//   engine_execute.cpp     running one operation and completing it
//   engine.cpp             the public API: submission, drain, statistics
//
// Phases of a worker (a C++20 coroutine run as oneTBB tasks):
//   idle      found no block it may serve; suspended. A submission to its home
//             (or, when it may steal, any busy block) resumes it as a new task,
//             and so does (when it may steal) a worker releasing a block that
//             still holds work: with a stream already all submitted, no
//             submission would come to wake it.
//   running   claims a non-empty block, serves up to `batch` of its operations,
//             releases it, claims the next; a rollback re-queues the operation
//             at the back of its block. A run of an insert_batch is served
//             point after point while the worker holds the block, and what
//             is left of it goes back to the front of the block when the
//             worker lets go, so the block's next holder goes on with it. A running worker that finds no block
//             to claim while much work waits in blocks others serve re-cuts
//             the blocks (rebalance, below) before it goes idle.
//   sleeping  suspended by the contention manager (progress ratio below u-);
//             woken by a worker whose ratio is above u+, a worker going idle,
//             a submission when nobody runs, or drain(). Its blocks may be
//             served by others meanwhile (stealing), so a sleeper never holds
//             work hostage.
// Rebalancing (a recut): the worker stops the world, claims every block (a
// holder lets go within one operation, which finds the world stopped; one
// that does not within 20 ms, a callback that blocks, cancels the recut),
// moves every queued record out, re-cuts the partition at the quantiles of
// their keys (a run weighs as many points as it has left), puts each back in
// its new block and restarts the world. It runs only when it can pay: at
// least `recut_min_pending` operations per worker are pending, and the workers
// completed since the last recut at least half the operations queued then.
// Invariants (checked in debug builds where they are local):
//   - a block is served by at most one worker: Block::holder;
//   - `active` counts running workers; a worker never sleeps when it is the
//     last one running, and a worker goes idle only after a scan, made after
//     it announced itself idle, found nothing it may serve: so while work is
//     pending some worker runs, or a submitter or drain() resumes one;
//   - a block with queued operations is marked in `nonempty` (NonEmptyBlocks);
//   - submitted (summed over shards) >= finished (summed over workers);
//     drain() returns when they are equal.
#include <oneapi/tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <coroutine>
#include <exception>
#include <memory>
#include <mutex>
#include <vector>

#include "block_queue.hpp"
#include "contention_manager.hpp"
#include "nonempty_blocks.hpp"
#include "op_record.hpp"
#include "partition.hpp"
#include "pdt/engine.hpp"
#include "stopped_world.hpp"
#include "tickets.hpp"
#include "triangulation_impl.hpp"

namespace pdt::detail {

// Reads a live vertex's point from any thread, without a context: one shared
// lock, taken only if free (a writer holds it exclusively while it changes
// the vertex). The answer is one observation of the lock word: `held` if a
// writer held it exclusively when looked at, else the shared lock was taken
// and the vertex read under it, `read` if it is a live vertex of the expected
// incarnation (0: any) and `dead` if not. (Checking "held?" again after a
// failed read would race: the writer may have let go in between.)
enum class VertexRead { read, held, dead };
inline VertexRead read_vertex(const Triangulation::Impl& m, VertexId v, std::uint64_t expected, Point3* p,
                              std::uint64_t* stamp) {
  std::atomic<std::int32_t>& lock = const_cast<Triangulation::Impl&>(m).verts[v].lock;
  std::int32_t cur = lock.load(std::memory_order_relaxed);
  do {
    if (cur < 0) return VertexRead::held;
  } while (!lock.compare_exchange_weak(cur, cur + 1, std::memory_order_acquire, std::memory_order_relaxed));
  const VertexRec& r = m.verts[v];
  *stamp = r.stamp.load(std::memory_order_relaxed);
  const bool ok = r.multiplicity > 0 && (expected == 0 || *stamp == expected);
  if (ok) *p = {r.p.x(), r.p.y(), r.p.z()};
  lock.fetch_sub(1, std::memory_order_release);
  return ok ? VertexRead::read : VertexRead::dead;
}

// read_vertex, for callers to whom held and dead are alike: true if read.
inline bool try_read_vertex(const Triangulation::Impl& m, VertexId v, std::uint64_t expected, Point3* p,
                            std::uint64_t* stamp) {
  return read_vertex(m, v, expected, p, stamp) == VertexRead::read;
}

// A worker's body: a coroutine that never returns; destroyed while suspended.
struct WorkerCoroutine {
  struct promise_type {
    WorkerCoroutine get_return_object() { return {std::coroutine_handle<promise_type>::from_promise(*this)}; }
    std::suspend_always initial_suspend() noexcept { return {}; }
    std::suspend_always final_suspend() noexcept { return {}; }
    void return_void() {}
    void unhandled_exception() { std::terminate(); }  // everything it calls catches its own errors
  };
  std::coroutine_handle<promise_type> handle;
};

enum class WorkerPhase : int { idle, running, sleeping };

struct alignas(64) Block {
  BlockQueue queue;
  std::atomic<int> holder{-1};            // the worker serving it, or -1
  std::atomic<std::uint32_t> queued{0};   // pushed and not popped (counted before the push; see count_in)
  unsigned home = 0;
};

struct alignas(64) Worker {
  Worker(unsigned i, std::uint32_t context_id, const EngineOptions& o)
      : index(i),
        ctx(std::make_unique<OpContext>(context_id, true)),
        contention(o.contention_low, o.contention_high, o.contention_window) {}

  unsigned index;
  std::unique_ptr<OpContext> ctx;
  // Read by every submission to this worker's blocks (enqueue): on a line of
  // its own, so that those reads do not take from the worker the line it
  // writes per operation (its contention manager), nor it theirs.
  alignas(64) std::atomic<WorkerPhase> phase{WorkerPhase::idle};
  alignas(64) std::coroutine_handle<> handle;
  ContentionManager contention;  // owned by the worker's running task
  // Home blocks are served in a sweep along the curve: the scan starts at the
  // block served last (home_cursor, relative to the home's first block), so
  // one worker keeps to one region, as a spatial sort would; after
  // `max_repeat` claims of the same block in a row it starts one further, so
  // a block that keeps receiving work cannot starve the others.
  std::uint32_t home_cursor = 0;
  std::uint32_t repeat = 0;  // claims of the home_cursor block in a row
  // Claims in a row of a home block whose first run was of a later BRIO
  // round than this worker's last run, put back (body); 0 once one is taken.
  std::uint32_t skipped = 0;
  std::uint32_t claims = 0;  // claims made (every 4th looks at orphaned blocks first)
  VertexId last_inserted = no_vertex;  // a batch insertion's walk starts here
  WalkWatch walks;  // this worker's recent walks (maybe_grow_grid)
  std::uint32_t walks_doublings = 0;  // EngineState::grid_doublings when `walks` was last re-armed
  // The batch point this worker took last: its batch (the BatchCallback's
  // address, compared only, never read through) and its position + 1. A run
  // that does not go on from there walks from the jump grid, not from
  // last_inserted, which may lie in another block across a dense region.
  std::uintptr_t batch_taken = 0;
  std::uint32_t batch_taken_end = 0;
  // A record kept for a run's next point when the pool cannot give one (out
  // of memory): with it a worker always makes progress, and the record it
  // frees on completion serves the next point. Refilled when the pool can.
  OpRecord* spare = nullptr;
  // Records this worker completed, kept (reset) for its runs' next points,
  // so that a batch's insertion takes no pool mutex to get a record and none
  // to give it back: at most kept_max, linked through OpRecord::next. Only
  // the worker's own task touches them (complete and take_from_run).
  static constexpr unsigned kept_max = 64;
  OpRecord* kept = nullptr;
  unsigned kept_count = 0;
  // Completed operations of one batch (insert_batch, remove_insertions) not
  // yet taken off its `remaining`: one atomic subtraction per claim, not one
  // per operation on a line every worker writes. Published at the end of
  // each claim (publish_batch_done), so before drain() returns. Invariant:
  // batch_done_count > 0 iff batch_done_unpublished != nullptr, and then
  // that batch's remaining >= batch_done_count (it is alive).
  BatchCallback* batch_done_unpublished = nullptr;
  std::uint64_t batch_done_count = 0;
  std::chrono::steady_clock::time_point slept_at;
  // Statistics: written by the worker, read by stats() (relaxed).
  std::atomic<std::uint64_t> completed{0}, attempts{0}, rollbacks{0}, deferred{0}, sleeps{0}, steals{0},
      escalated{0};
  std::atomic<double> seconds_asleep{0};
  // Idle time: seconds_idle sums the stretches that ended; idle_since_ns is
  // when the one under way began (steady_ns()), 0 when the worker is not
  // idle, so that stats() counts it too. A worker is idle from the engine's
  // construction until its body first runs, and in IdleAwait. Written only
  // by the worker's own task (the constructor, before any runs), through
  // begin_idle / end_idle; stats() reads idle_since_ns first (acquire).
  std::atomic<double> seconds_idle{0};
  std::atomic<std::int64_t> idle_since_ns{0};
  void begin_idle(std::int64_t now_ns) { idle_since_ns.store(now_ns, std::memory_order_relaxed); }
  // The sum is stored before the start is cleared (release): a stats()
  // meanwhile may count the stretch twice for a moment, never drop it.
  void end_idle(std::int64_t now_ns) {
    const std::int64_t since = idle_since_ns.load(std::memory_order_relaxed);
    if (since == 0) return;
    seconds_idle.store(seconds_idle.load(std::memory_order_relaxed) + 1e-9 * double(now_ns - since),
                       std::memory_order_release);
    idle_since_ns.store(0, std::memory_order_release);
  }
  std::atomic<std::uint64_t> finished{0};  // operations whose results were delivered
};

// steady_clock now, in nanoseconds since its epoch; never 0 (Worker::idle_since_ns).
inline std::int64_t steady_ns() {
  const std::int64_t ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
  return ns > 0 ? ns : 1;
}

struct EngineState {
  EngineState(Triangulation& t, const Box& d, EngineOptions o, unsigned workers, unsigned blocks, tbb::task_arena* a);
  ~EngineState();

  Triangulation::Impl& impl;
  Box domain;
  EngineOptions opts;
  tbb::task_arena attached;  // the caller's arena when none is passed
  tbb::task_arena* arena;
  // Isolated: a cancellation in the submitter's context (a parallel_for whose
  // body throws) does not reach the engine's tasks.
  tbb::task_group_context group_context{tbb::task_group_context::isolated};
  tbb::task_group tasks{group_context};
  unsigned nworkers;
  Partition partition;
  std::unique_ptr<Block[]> blocks;
  NonEmptyBlocks nonempty;  // which blocks may hold work: what claim() and work_for() scan
  // Operations submitted, ever, in shards (a block's shard: its index mod
  // submit_shards), so that submitters on many threads do not share one
  // line and in_flight() reads a few counters, not every block.
  static constexpr std::uint32_t submit_shards = 64;
  struct alignas(64) SubmitCount {
    std::atomic<std::uint64_t> n{0};
  };
  std::unique_ptr<SubmitCount[]> submitted;
  std::vector<std::unique_ptr<Worker>> workers;
  std::vector<WorkerCoroutine> bodies;
  TicketTable tickets;
  OpRecordPool records;
  StoppedWorld world;
  std::mutex sleep_mutex;
  std::vector<Worker*> sleepers;  // room for every worker: pushing never allocates
  std::atomic<int> active{0};
  std::atomic<int> idle_count{0};
  std::atomic<std::uint64_t> global_ops{0};
  // Rebalancing: recuts done, and the completed count before which none runs.
  std::atomic<std::uint64_t> recuts{0};
  std::atomic<std::uint64_t> recut_after{0};
  // The recutting worker's scratch (with the world stopped, by its stopper):
  // a sample of the queued keys, reserved once when recuts may happen.
  std::vector<std::uint64_t> recut_keys;
  // Vertex-id bound at which the jump grid is regrown: each time the vertex
  // ids double, so it always holds about two vertices per slot.
  std::atomic<std::size_t> grid_grow_at{0};
  // The grid's built_for and whether its slots could grow (asked for fewer
  // than the cap): what a worker outside the stopped world may read of it
  // (maybe_grow_grid), set with the grid.
  std::atomic<std::size_t> grid_built_for{0};
  std::atomic<bool> grid_may_grow{true};
  std::atomic<std::uint32_t> grid_doublings{0};  // rebuilds as the ids grew (WalkWatch::rearm)
  // Set once a worker's walks stayed long (WalkWatch): from then on every
  // rebuild cuts the crowded slots (build_split), never equal slots alone
  // (with the world stopped, by its stopper).
  bool grid_follows = false;
  // The change hook, and the wrapper the kernel calls (it catches).
  ChangeHook user_hook;
  ChangeHook kernel_hook;
  // The first exception a callback, hook or resumed coroutine threw.
  std::mutex client_error_mutex;
  std::exception_ptr first_client_error;
  std::atomic<std::uint64_t> client_errors{0};

  static constexpr std::uint32_t batch = 64;  // operations served per block claim
  static constexpr std::uint32_t max_repeat = 16;  // claims of one home block in a row
  static constexpr std::uint32_t max_run = 256;    // points of an insert_batch run
  static constexpr std::uint64_t recut_min_pending = 2 * batch;  // pending operations per worker, for a recut to pay
  static constexpr std::size_t recut_sample_per_block = 32;      // keys sampled per block

  // -- submission (engine.cpp) ---------------------------------------------------
  OpRecord* make_insert(const Point3& p);
  // tickets.sweep_if_large against the live vertex count (before issuing).
  void sweep_tickets() {
    tickets.sweep_if_large(impl.verts, static_cast<std::uint64_t>(std::max<std::int64_t>(0, impl.n_vertices.load())));
  }
  OpRecord* make_remove(VertexHandle v);
  // Routes op to its block; it stands for `count` operations (a run: its points).
  void submit(OpRecord* op, std::uint32_t count = 1);
  // The record of an undo of ticket t (claimed: view); throws only
  // std::bad_alloc, before anything changed.
  OpRecord* make_undo(std::uint64_t t, const TicketView& view, Engine::Callback done, BatchCallback* batch_done);
  void record_client_error(std::exception_ptr e);
  // Runs client code on a worker (a callback, a visitor; the change hook
  // does the same): what it throws is counted, not propagated.
  template <class F>
  void run_client(F&& f) {
    try {
      f();
    } catch (...) {
      record_client_error(std::current_exception());
    }
  }

  // -- scheduling (engine_scheduler.cpp) -----------------------------------------
  // Runs h (a worker body or a coroutine awaiting a result) as a task of
  // `tasks`, marked as this engine's so drain() can refuse to wait for itself.
  // An exception escaping h is a client error.
  void spawn(std::coroutine_handle<> h);
  // The engine whose task the current thread is running, if any.
  static thread_local const EngineState* running_engine;
  // Operations (of any engine) the current thread is inside (run_op). A
  // hook or visitor runs inside its operation, and one that enters the arena
  // again (task_arena::execute, to run a parallel_for "in my arena") lets
  // the thread take the engines' queued tasks while it waits; a worker body
  // run there, on top of the operation, could wait for that operation to end
  // (stopping the world waits for every worker to leave its operation) or
  // roll back on its locks without end: a deadlock. So while this is not 0,
  // spawn's tasks do not run here: each is queued again, for a thread
  // outside any operation.
  static thread_local unsigned ops_on_this_thread;
  void enqueue(Block& b, OpRecord* op);  // push and make sure someone serves b (op already counted)
  // Pushes op into b, counted first in b.queued and then marked in `nonempty`
  // (the order NonEmptyBlocks relies on, seq_cst). Every push goes through
  // here or count_in_front.
  void count_in(Block& b, OpRecord* op);
  // The same at the front of b's queue, by b's holder: what is left of a run
  // it was serving, so that whoever serves b next goes on with that run (at
  // the back, the block's other runs would each be served a slice in turn,
  // the walk jumping between them: 30% of a 1M batch on one worker).
  void count_in_front(Block& b, OpRecord* op);
  std::uint32_t index_of(const Block& b) const { return static_cast<std::uint32_t>(&b - blocks.get()); }
  void resume(Worker& w);  // w was idle or asleep: mark it running and resume it as a task
  bool wake_one();         // a sleeper, if any
  bool wake_idle();        // an idle worker, if any (to take over busy blocks)
  void wake_locked(Worker& w);  // takes w off `sleepers` (caller holds sleep_mutex)
  bool may_serve(const Worker& w, const Block& b) const;
  Block* claim(Worker& w);       // a non-empty block w may serve, claimed; or null
  bool work_for(const Worker& w) const;  // is there a block w may claim?
  void release(Block& b);
  std::uint64_t completed_total() const;
  // Worker w (holding no block, in no operation) found nothing to claim:
  // re-cut the blocks if work piles up where others are. True if it did.
  bool maybe_recut(Worker& w);
  // The next point of a run (held by worker w, not queued) as a record of
  // its own; the run is released after its last point. Null only when
  // neither the pool nor w's spare has a record (the run stays as it was).
  OpRecord* take_from_run(Worker& w, OpRecord*& run);
  bool idle_everywhere() const;  // no operation pending
  std::uint64_t in_flight() const;
  WorkerCoroutine body(Worker& w);

  // -- running one operation (engine_execute.cpp) ------------------------------------
  // done: completed; rollback: met a lock (the body re-queues it); parked:
  // handed on (waiting on its ticket, or moved to its block); global: the
  // world is stopped (re-queued; the worker waits for the restart).
  enum class Outcome { done, rollback, parked, global };
  Outcome execute(Worker& w, OpRecord* op);
  // The kernel call of one operation in ctx.
  OpStatus run_op(Worker& w, OpContext& ctx, OpRecord& op, OpResult& r, std::uint64_t& stamp);
  // Runs op with the world stopped; false if another worker holds the world
  // (op untouched: re-queue it).
  bool run_global(Worker& w, OpRecord* op, bool escalated = false);
  void complete(Worker& w, OpRecord* op, OpResult& r, std::uint64_t stamp);
  // Takes w's unpublished completions off their batch's remaining, deleting
  // the batch when that was the last (see Worker::batch_done_unpublished).
  void publish_batch_done(Worker& w);

  // -- the jump grid's growth, with the world stopped ---------------------------------
  // With the world stopped (parallel: in the arena, whose other workers are
  // suspended), or before workers run.
  // follow: now, and cut where crowded from now on (a worker's walks stayed long).
  void ensure_grid(bool parallel = false, bool follow = false, bool shrunk = false);
  void maybe_grow_grid(Worker& w);
};

}  // namespace pdt::detail
