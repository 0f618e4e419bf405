#pragma once
// pdt::Engine: many workers carrying out a live stream of insertions and
// removals on one Triangulation (Foteinos & Chrisochoides, §3).
//
// Model. The engine is given the domain box up front; the box is split into
// blocks_per_axis^3 blocks, each owned by one worker with its own queue, and
// every operation goes to the worker owning its point's block (a removal: the
// vertex's point). Workers run as oneTBB tasks in the caller's task_arena (the
// arena the constructing thread is in, or the one passed): no hidden thread
// pool. A worker takes per-vertex try-locks (shared while walking, exclusive
// on a cavity or hole); when a lock is taken it rolls the operation back
// (nothing was changed), puts it back in its queue and moves on. A contention
// manager keeps each worker's progress ratio completed/attempted: below
// contention_low the worker suspends (releasing everything), above
// contention_high it wakes a sleeper; at least one worker always runs, so the
// engine cannot livelock. Because ties are broken by symbolic perturbation the
// final triangulation does not depend on the worker count or the interleaving.
//
// Any thread may submit while the engine runs. Results come back three ways:
//   co_await engine.insert(p)            (C++20 coroutine; resumes as a TBB task)
//   engine.insert(p, callback)           (callback on a worker thread; keep it short)
//   engine.drain()                       (waits until every submitted operation is done)
// While an engine runs, do not call the Triangulation's mutating methods or
// queries directly; after drain() they see the final state.
#include <coroutine>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <oneapi/tbb/task_arena.h>

#include "pdt/engine_options.hpp"
#include "pdt/geometry.hpp"
#include "pdt/triangulation.hpp"

namespace pdt {

struct WorkerStats {
  std::uint64_t completed = 0;  // operations done
  std::uint64_t attempts = 0;   // tries, completed + rolled back + deferred
  std::uint64_t rollbacks = 0;  // tries that met a lock
  std::uint64_t deferred = 0;   // removals tried before the insertion they undo was done
  std::uint64_t sleeps = 0;     // times the contention manager suspended this worker
  double seconds_asleep = 0;
  double max_rollbacks_per_completed = 0;  // the paper's "Max #Rollbacks/#compl. ops", per worker
};

struct EngineStats {
  std::vector<WorkerStats> workers;
  std::uint64_t global_operations = 0;  // run with the world stopped (dimension changes)
  WorkerStats total() const;            // sums; max ratio is the max over workers
};

// Which kind of operation an OpResult reports.
enum class OpKind : std::uint8_t {
  insert,            // insert(p), insert_batch
  remove,            // remove(v)
  remove_insertion,  // remove_insertion(t), remove_insertions
};

// The outcome of one operation.
struct OpResult {
  OpKind kind = OpKind::insert;
  InsertResult insert;                               // for insertions
  RemoveResult remove = RemoveResult::removed;       // for removals
  std::exception_ptr error;                          // a pdt::Error if the operation failed
  std::uint64_t ticket = ~std::uint64_t{0};          // insertions and their undos: the insertion's ticket
};

class Engine;

namespace detail {
struct EngineState;
struct OpAwaitBase {
  Engine* engine;
  OpResult result;
  std::coroutine_handle<> waiter;
};
}  // namespace detail

class [[nodiscard]] InsertAwaitable : detail::OpAwaitBase {
 public:
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h);  // false: failed at once, await_resume throws
  InsertResult await_resume();  // rethrows the operation's error

 private:
  friend class Engine;
  Point3 point_;
};

class [[nodiscard]] RemoveAwaitable : detail::OpAwaitBase {
 public:
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h);
  RemoveResult await_resume();  // rethrows the operation's error

 private:
  friend class Engine;
  VertexId vertex_ = no_vertex;
};

class Engine {
 public:
  using Callback = std::function<void(const OpResult&)>;
  using Ticket = std::uint64_t;  // numbers the insertions submitted to this engine, from 0

  // The triangulation must outlive the engine; points outside `domain` are
  // refused. arena: where workers run; null = the caller's current arena.
  Engine(Triangulation& t, const Box& domain, EngineOptions options = EngineOptions::from_environment(),
         tbb::task_arena* arena = nullptr);
  ~Engine();  // drains; so never destroy an engine from its own callbacks or coroutines
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // Awaitable forms. Errors (NaN, outside the domain) are thrown by co_await.
  InsertAwaitable insert(const Point3& p);
  RemoveAwaitable remove(VertexId v);
  // Callback forms (callback may be empty). insert() throws pdt::Error at once
  // for a NaN/Inf point or one outside the domain, and submits nothing.
  Ticket insert(const Point3& p, Callback done);
  void remove(VertexId v, Callback done);
  // A batch of insertions, submitted in spatial order (CGAL's spatial sort,
  // parallel in the engine's arena, as CGAL's range insertion does): each
  // worker then walks from its previous vertex, about twice as fast as a
  // random order. Insertion first + i inserts points[i]; first is returned.
  // Checks every point first: throws pdt::Error for a NaN/Inf point or one
  // outside the domain and submits nothing. done (may be empty) is called
  // once per insertion; OpResult::ticket says which.
  Ticket insert_batch(std::span<const Point3> points, Callback done = {});
  // The result of insertion t once it has finished (after drain(), or in
  // anything its callback or co_await started). Throws pdt::Error
  // (invalid_argument) for a ticket never issued or not finished, and
  // rethrows the insertion's own error if it failed.
  InsertResult insertion_result(Ticket t) const;
  // Undoes insertion `t` of this engine; it waits for that insertion to finish
  // first, so a stream can be replayed without barriers. Throws at once for a
  // ticket never issued or already undone.
  void remove_insertion(Ticket t, Callback done = {});
  // A batch of undos, submitted in spatial order (as insert_batch). All or
  // nothing: throws, and undoes nothing, if any ticket was never issued, is
  // already undone or appears twice.
  void remove_insertions(std::span<const Ticket> tickets, Callback done = {});

  // Returns when no operation is pending: every one submitted before the call
  // is done (and those other threads submit meanwhile, so a producer that
  // never pauses keeps it waiting). Throws pdt::Error(invalid_argument) when
  // called from this engine's own callbacks or from a coroutine it resumed:
  // there it would wait for itself.
  void drain();
  EngineStats stats() const;
  unsigned workers() const;
  [[deprecated("use workers()")]] unsigned threads() const { return workers(); }
  unsigned blocks_per_axis() const;
  const EngineOptions& options() const;

 private:
  friend class InsertAwaitable;
  friend class RemoveAwaitable;
  std::unique_ptr<detail::EngineState> state_;
};

}  // namespace pdt
