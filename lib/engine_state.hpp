#pragma once
// The engine's state, by room:
//   partition.hpp          blocks of the domain -> workers (routing)
//   op_record.hpp          submitted operations and their pool
//   tickets.hpp            insertions by ticket, and undos waiting for them
//   contention_manager.hpp the progress ratio and its verdicts
//   stopped_world.hpp      running alone (dimension changes, grid growth)
//   engine_workers.cpp     the workers: coroutine bodies, phases, wake-ups,
//                          running one operation and completing it
//   engine.cpp             the public API: submission, drain, statistics
//
// Phases of a worker (a C++20 coroutine run as TBB tasks):
//   idle      its queue was empty; suspended. A submission to its queue
//             resumes it as a new task.
//   running   pops operations and runs them; a rollback re-queues the
//             operation at the back of its own queue.
//   sleeping  suspended by the contention manager (progress ratio below u-);
//             woken by a worker whose ratio is above u+, or by any worker
//             going idle, or by drain().
// Invariants:
//   - `active` counts running workers; a worker never goes to sleep when it is
//     the last one running, so while work is pending some worker runs (or a
//     sleeper holds it and drain() wakes it).
//   - per worker, finished <= submitted; drain() returns when they are equal
//     for every worker.
#include <boost/lockfree/queue.hpp>
#include <oneapi/tbb/task_group.h>

#include <atomic>
#include <chrono>
#include <coroutine>
#include <memory>
#include <mutex>
#include <vector>

#include "contention_manager.hpp"
#include "op_record.hpp"
#include "partition.hpp"
#include "pdt/engine.hpp"
#include "stopped_world.hpp"
#include "tickets.hpp"
#include "triangulation_impl.hpp"

namespace pdt::detail {

// A worker's body: a coroutine that never returns; destroyed while suspended.
struct WorkerCoroutine {
  struct promise_type {
    WorkerCoroutine get_return_object() { return {std::coroutine_handle<promise_type>::from_promise(*this)}; }
    std::suspend_always initial_suspend() noexcept { return {}; }
    std::suspend_always final_suspend() noexcept { return {}; }
    void return_void() {}
    void unhandled_exception() { std::terminate(); }  // operations catch their own errors
  };
  std::coroutine_handle<promise_type> handle;
};

enum class WorkerPhase : int { idle, running, sleeping };

struct alignas(64) Worker {
  Worker(unsigned i, std::uint32_t context_id, const EngineOptions& o)
      : index(i),
        ctx(std::make_unique<OpContext>(context_id, true)),
        contention(o.contention_low, o.contention_high, o.contention_window) {}

  unsigned index;
  std::unique_ptr<OpContext> ctx;
  // Boost.Lockfree over oneTBB's concurrent_queue: 2x the throughput with one
  // producer and far better when threads outnumber cores (bench_queues).
  boost::lockfree::queue<OpRecord*> queue{256};
  std::atomic<WorkerPhase> phase{WorkerPhase::idle};
  std::coroutine_handle<> handle;
  ContentionManager contention;  // owned by the worker's running task
  VertexId last_inserted = no_vertex;  // a batch insertion's walk starts here
  std::chrono::steady_clock::time_point slept_at;
  // Statistics: written by the worker, read by stats() (relaxed).
  std::atomic<std::uint64_t> completed{0}, attempts{0}, rollbacks{0}, deferred{0}, sleeps{0};
  std::atomic<double> seconds_asleep{0};
  // Operations routed here, counted by submitters before the push (its own
  // cache line: submitters write it, the worker never does), and operations
  // finished, counted by the worker after their results are delivered.
  std::atomic<std::uint64_t> finished{0};
  alignas(64) std::atomic<std::uint64_t> submitted{0};
};

struct EngineState {
  EngineState(Triangulation& t, const Box& d, EngineOptions o, unsigned workers, unsigned blocks, tbb::task_arena* a);

  Triangulation::Impl& impl;
  Box domain;
  EngineOptions opts;
  tbb::task_arena attached;  // the caller's arena when none is passed
  tbb::task_arena* arena;
  tbb::task_group tasks;
  unsigned nworkers;
  Partition partition;
  std::vector<std::unique_ptr<Worker>> workers;
  std::vector<WorkerCoroutine> bodies;
  TicketTable tickets;
  OpRecordPool records;
  StoppedWorld world;
  std::mutex sleep_mutex;
  std::vector<Worker*> sleepers;
  std::atomic<int> active{0};
  std::atomic<std::uint64_t> global_ops{0};
  // Vertex-id bound at which the jump grid is regrown: each time the vertex
  // ids double, so it always holds about two vertices per slot.
  std::atomic<std::size_t> grid_grow_at{0};

  // -- submission (engine.cpp) ---------------------------------------------------
  OpRecord* make_insert(const Point3& p);
  OpRecord* make_remove(VertexId v);
  void submit(OpRecord* op);
  void submit_undo(std::uint64_t t, const Engine::Callback& done);

  // -- scheduling (engine_workers.cpp) -------------------------------------------
  // Runs h (a worker body or a coroutine awaiting a result) as a task of
  // `tasks`, marked as this engine's so drain() can refuse to wait for itself.
  void spawn(std::coroutine_handle<> h);
  // The engine whose task the current thread is running, if any.
  static thread_local const EngineState* running_engine;
  void enqueue(Worker& w, OpRecord* op);  // push and make sure w will run (op already counted)
  void resume(Worker& w);  // w was idle or asleep: mark it running and resume it as a task
  bool wake_one();
  void wake_locked(Worker& w);  // takes w off `sleepers` (caller holds sleep_mutex)
  bool idle_everywhere() const;  // no operation pending on any worker
  WorkerCoroutine body(Worker& w);

  // -- running one operation (engine_workers.cpp) ------------------------------------
  // The kernel call of one operation in ctx; the removal of a ticket uses the
  // vertex its insertion produced.
  OpStatus run_op(Worker& w, OpContext& ctx, OpRecord& op, OpResult& r, std::uint64_t& stamp);
  void execute(Worker& w, OpRecord* op);
  void run_global(Worker& w, OpRecord* op);
  void complete(Worker& w, OpRecord* op, OpResult& r, std::uint64_t stamp);

  // -- the jump grid's growth (engine_workers.cpp) -----------------------------------
  void ensure_grid();  // with the world stopped (or before workers run)
  void maybe_grow_grid(Worker& w);
};

}  // namespace pdt::detail
