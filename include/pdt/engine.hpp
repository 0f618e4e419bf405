// SPDX-License-Identifier: MIT
#pragma once
// pdt::Engine: many workers carrying out a live stream of insertions and
// removals on one Triangulation (Foteinos & Chrisochoides, §3), in the
// caller's oneTBB arena.
//
// Model. The engine is given the domain box up front; the box is cut into
// blocks_per_axis^3 blocks, numbered along a Morton curve, and every operation
// goes to the queue of its point's block (a removal: the vertex's point).
// Each worker has a home: a run of neighbouring blocks, which it serves first;
// a worker with nothing at home takes over a non-empty block from elsewhere
// (nearest first), so work that concentrates or moves still uses every worker.
// A block is served by one worker at a time. Workers are C++20 coroutines run
// as oneTBB tasks in the caller's task_arena (the arena the constructing
// thread is in, or the one passed): no hidden thread pool, and a worker with
// nothing to do is suspended, not blocking a thread. A worker takes
// per-vertex try-locks (shared while walking, exclusive on a cavity or hole);
// when a lock is taken it rolls the operation back (nothing was changed),
// puts it back in its block's queue and moves on. A contention manager keeps
// each worker's progress ratio completed/attempted: below contention_low the
// worker suspends, above contention_high it wakes a sleeper; the last running
// worker never sleeps. An operation rolled back escalate_after times runs
// with the world stopped, alone, so it completes. Because ties are broken by
// symbolic perturbation the final triangulation does not depend on the worker
// count or the interleaving.
//
// The contract.
//  - Lifetime. An Engine attaches to its Triangulation for its whole life:
//    the triangulation must outlive it, only one engine at a time may be
//    attached (a second is refused with pdt::Error), and the triangulation's
//    mutators (insert, remove, clear, move, set_change_hook) are refused while
//    it is attached. Engines may come and go on one triangulation, with
//    sequential work in between; each leaves it valid. An awaitable
//    (engine.insert(p) and friends) names the engine that made it, as a
//    reference does: await it while that engine lives. One awaited after
//    the engine is destroyed is not detected (undefined behaviour, as for a
//    dangling reference; an engine built since at the same address may even
//    take it).
//  - Threads. Any thread may submit at any time, including from callbacks,
//    hooks and coroutines the engine resumed. Submitting never waits for the
//    engine's workers (a submitter may hold a lock a hook also takes). drain(), stats() and
//    in_flight() may be called from any thread outside the engine's work.
//    The triangulation's const queries are safe after drain() returns and
//    before the next submission; while operations are in flight, read through
//    the engine: locate, nearest_vertex and visit take shared locks and retry
//    on conflict.
//  - Results come back three ways: co_await engine.insert(p) (the coroutine
//    resumes as a TBB task), engine.insert(p, callback) (the callback runs on
//    a worker: keep it short), and drain() (waits until every operation
//    submitted before it is done).
//  - Exceptions. Bad input is refused at submission (the callback forms
//    throw, the awaitable forms throw from co_await) and submits nothing. An
//    operation that fails in flight reports its error in OpResult::error. An
//    exception thrown by a callback, a change hook or a coroutine the engine
//    resumed is caught, counted (EngineStats::client_errors), and the first
//    one is rethrown by the next drain(); the engine goes on working. A
//    coroutine whose exception escapes ends suspended at its final point;
//    the engine does not own its frame and leaves it to the handle's owner
//    (a detached coroutine type leaks it: catch inside where that matters).
//  - What cannot be refused: a callback or hook that blocks until another
//    thread's drain() returns, or until an operation it submitted completes,
//    waits for itself (drain() waits for the callback) and hangs. Callbacks
//    must not wait for the engine; co_await instead. drain() and the
//    destructor called from the engine's own work are detected and refused.
//    Parallel work a callback starts and waits for (a tbb::parallel_for,
//    a task_group) counts as the callback: drain() in it is refused where it
//    runs on the callback's own thread, and hangs where another thread runs
//    it, since the callback then waits for that drain(). Such work may run
//    in the engine's own arena (task_arena::execute from a hook, a visitor
//    or a callback): a thread waiting for it inside an operation never takes
//    the engine's tasks, which other threads run instead.
#include <coroutine>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <oneapi/tbb/task_arena.h>

#include "pdt/changes.hpp"
#include "pdt/engine_options.hpp"
#include "pdt/geometry.hpp"
#include "pdt/triangulation.hpp"

namespace pdt {

struct WorkerStats {
  std::uint64_t completed = 0;  // operations done
  std::uint64_t attempts = 0;   // tries that ran: completed + rolled back
  std::uint64_t rollbacks = 0;  // tries that met a lock held by another worker
  std::uint64_t deferred = 0;   // undos that arrived before the insertion they undo was done (parked)
  std::uint64_t sleeps = 0;     // times the contention manager suspended this worker
  std::uint64_t steals = 0;     // blocks it served away from its home
  std::uint64_t escalated = 0;  // operations it ran with the world stopped after escalate_after rollbacks
  double seconds_asleep = 0;
  // Waiting for work: suspended with no block it could claim, or not started
  // yet. Exact when no worker runs (after drain()); while they run, a stretch
  // ending at that moment may be counted twice in one snapshot.
  double seconds_idle = 0;
  double max_rollbacks_per_completed = 0;  // the paper's "Max #Rollbacks/#compl. ops", per worker
};

struct EngineStats {
  std::vector<WorkerStats> workers;
  std::uint64_t global_operations = 0;  // run with the world stopped (dimension changes, escalations)
  std::uint64_t client_errors = 0;      // exceptions from callbacks, hooks and resumed coroutines
  std::uint64_t recuts = 0;             // times the blocks were re-cut to where the work is (rebalance)
  WorkerStats total() const;            // sums; max ratio is the max over workers
  // Load balance: max over workers of completed operations / the mean (1 = even).
  double imbalance() const;
};

// The outcome of one operation; `kind` says which fields mean something.
struct OpResult {
  OpKind kind = OpKind::insert;
  InsertResult insert;                          // insert
  RemoveResult remove = RemoveResult::removed;  // remove, remove_insertion
  LocateResult locate;                          // locate
  VertexId nearest = no_vertex;                 // nearest_vertex
  bool alive = false;                           // visit: the cell was live (and fn ran)
  std::exception_ptr error;                     // a pdt::Error if the operation failed
  std::uint64_t ticket = ~std::uint64_t{0};     // insertions and their undos: the insertion's ticket
  std::uint32_t rollbacks = 0;                  // times it met a lock before it completed
  bool escalated = false;                       // it then ran with the world stopped
};

class Engine;

// A function run on a cell under the engine's locks (Engine::visit).
using CellVisitor = std::function<void(const CellView&)>;

namespace detail {
struct EngineState;
// What an awaitable asks the engine for.
struct Request {
  OpKind kind = OpKind::insert;
  Point3 point;
  VertexHandle vertex;  // remove: incarnation 0 = whichever is live now
  CellHandle cell;      // visit; insert: only if this cell is alive (when only_if_alive)
  CellVisitor visitor;  // visit
  bool only_if_alive = false;
};
// One operation: submitted by its first co_await. So it is move-only (a
// copy would be a second submission of the same request), and awaiting it
// again, or awaiting what it was moved from (or one default-constructed),
// is refused (pdt::Error, invalid_argument, from the co_await) rather than
// run twice. Invariant: engine == nullptr once moved from (and until an
// Engine method fills it in); awaited once submitted.
struct OpAwaitBase {
  Engine* engine = nullptr;
  Request request;
  OpResult result;
  std::coroutine_handle<> waiter;
  bool awaited = false;
  OpAwaitBase() = default;
  OpAwaitBase(const OpAwaitBase&) = delete;
  OpAwaitBase& operator=(const OpAwaitBase&) = delete;
  OpAwaitBase(OpAwaitBase&& o) noexcept
      : engine(std::exchange(o.engine, nullptr)),
        request(std::move(o.request)),
        result(std::move(o.result)),
        waiter(o.waiter),
        awaited(o.awaited) {}
  OpAwaitBase& operator=(OpAwaitBase&& o) noexcept {
    engine = std::exchange(o.engine, nullptr);
    request = std::move(o.request);
    result = std::move(o.result);
    waiter = o.waiter;
    awaited = o.awaited;
    return *this;
  }
  ~OpAwaitBase() = default;
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h);  // false: refused at once; await_resume throws
};
inline void take(const OpResult& r, InsertResult& out) { out = r.insert; }
inline void take(const OpResult& r, RemoveResult& out) { out = r.remove; }
inline void take(const OpResult& r, LocateResult& out) { out = r.locate; }
inline void take(const OpResult& r, VertexId& out) { out = r.nearest; }
inline void take(const OpResult& r, bool& out) { out = r.alive; }
}  // namespace detail

// co_await engine.insert(p) and friends: T is what co_await gives. Each is
// one operation, run when first awaited: move-only, awaited once (OpAwaitBase).
template <class T>
class [[nodiscard]] OpAwaitable : public detail::OpAwaitBase {
 public:
  T await_resume() {  // rethrows the operation's error
    if (result.error) std::rethrow_exception(result.error);
    T out{};
    detail::take(result, out);
    return out;
  }
};
using InsertAwaitable = OpAwaitable<InsertResult>;
using RemoveAwaitable = OpAwaitable<RemoveResult>;
using LocateAwaitable = OpAwaitable<LocateResult>;
using NearestAwaitable = OpAwaitable<VertexId>;
using VisitAwaitable = OpAwaitable<bool>;

class Engine {
 public:
  using Callback = std::function<void(const OpResult&)>;
  using Ticket = std::uint64_t;  // numbers the insertions submitted to this engine, from 0

  // Attaches to t. Points outside `domain` are refused. Vertices t already
  // has outside it stay, and may be removed through the engine (their
  // operations go to the nearest block). arena: where workers
  // run (it must outlive the engine, as t must); null = the caller's current
  // arena, attached. An arena whose slots are all reserved for application
  // threads (task_arena(n, n) with n >= 2) gets no oneTBB worker thread: the
  // engine's work there runs only while an application thread is inside it
  // (in drain(), or in arena.execute), so callbacks and co_await wait until
  // then. Throws pdt::Error(invalid_argument)
  // for a bad domain or option, or when another engine is attached to t.
  Engine(Triangulation& t, const Box& domain, EngineOptions options = EngineOptions::from_environment(),
         tbb::task_arena* arena = nullptr);
  // Drains (client errors not collected by a drain() are dropped: see
  // stats()), then detaches. Called from the engine's own callbacks or
  // coroutines it throws pdt::Error instead: the engine cannot destroy the
  // work that is running it. It is then left running and leaked, still
  // attached to t, whose workers may still read it: t must then be leaked
  // too (never destroyed); it refuses every change from then on.
  // Every submitting call made from other threads (insert, remove, ...) must
  // have returned first: an operation's callback may run before the call
  // that submitted it returns.
  ~Engine() noexcept(false);
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // -- awaitable forms: errors (NaN, outside the domain, a dead vertex) are
  //    thrown by co_await ---------------------------------------------------------
  InsertAwaitable insert(const Point3& p);
  // Inserts p only if cell h is still alive when the insertion runs (a
  // refiner inserting a bad cell's circumcentre: if the cell died meanwhile,
  // nothing is inserted and co_await gives {no_vertex, false}). The check and
  // the insertion are one operation. Such an insertion has no ticket.
  InsertAwaitable insert_if_alive(const Point3& p, CellHandle h);
  RemoveAwaitable remove(VertexId v);
  // That incarnation only; incarnation 0 (an empty handle's) names whichever
  // is live, as remove(v.id) does (Triangulation::remove(VertexHandle)
  // refuses it: there a handle must come from the triangulation).
  RemoveAwaitable remove(VertexHandle v);
  LocateAwaitable locate(const Point3& p);
  NearestAwaitable nearest_vertex(const Point3& p);  // no_vertex if empty
  // Runs fn on h's cell under the engine's locks if that incarnation is still
  // live; co_await gives whether it was (false: dead, fn not called). fn runs
  // on a worker; what it throws is a client error (counted, rethrown by the
  // next drain()), not the operation's: the visit still gives true.
  VisitAwaitable visit(CellHandle h, CellVisitor fn);

  // -- callback forms (callback may be empty): bad input throws pdt::Error at
  //    once and submits nothing ------------------------------------------------------
  Ticket insert(const Point3& p, Callback done);
  void insert_if_alive(const Point3& p, CellHandle h, Callback done);
  void remove(VertexId v, Callback done);
  void remove(VertexHandle v, Callback done);
  void locate(const Point3& p, Callback done);
  void nearest_vertex(const Point3& p, Callback done);
  void visit(CellHandle h, CellVisitor fn, Callback done);
  // A batch of insertions, submitted in spatial order (a biased randomized
  // insertion order along a Hilbert curve, computed in parallel in the
  // caller's arena, so that submitting never waits for the engine's threads; as
  // CGAL's range insertion orders its points): each
  // worker then walks from its previous vertex, about twice as fast as a
  // random order. Insertion first + i inserts points[i]; first is returned.
  // Checks every point first: throws pdt::Error for a NaN/Inf point or one
  // outside the domain and submits nothing. done (may be empty) is called
  // once per insertion; OpResult::ticket says which.
  Ticket insert_batch(std::span<const Point3> points, Callback done = {});
  // The result of insertion t once it has finished (after drain(), or in
  // anything its callback or co_await started). Throws pdt::Error
  // (invalid_argument) for a ticket never issued, not finished, or released,
  // and rethrows the insertion's own error if it failed.
  InsertResult insertion_result(Ticket t) const;
  // Undoes insertion `t` of this engine; it waits for that insertion to finish
  // first, so a stream can be replayed without barriers. Throws pdt::Error
  // (unknown_vertex: there is no insertion to undo) at once for a ticket
  // never issued, already undone, or released.
  void remove_insertion(Ticket t, Callback done = {});
  // A batch of undos, submitted in spatial order (as insert_batch). All or
  // nothing: throws, and undoes nothing, if any ticket was never issued, is
  // already undone or appears twice, or if memory runs out while the batch is
  // prepared (std::bad_alloc); every ticket can then be undone again.
  void remove_insertions(std::span<const Ticket> tickets, Callback done = {});
  // Tickets cost memory only while they can still be used: a ticket is
  // released once its insertion is undone, or once its vertex is gone
  // (removed by handle or id); then insertion_result and remove_insertion
  // refuse it. A removal by handle or id undoes one insertion of a vertex
  // but no particular ticket, so it releases none: a vertex inserted k times
  // and lowered by handle keeps its k tickets (and their memory) until it is
  // gone, and undoing more of them than it has insertions left fails in
  // flight (OpResult::error, unknown_vertex), which remove_insertions'
  // all-or-nothing check cannot see. Undo a vertex's insertions one way.

  // Calls hook inside every later operation that creates or deletes a vertex
  // (changes.hpp), on the worker that runs it. Set it before submitting:
  // throws pdt::Error(invalid_argument) while operations are in flight. The
  // refusal is a check, not a lock: no other thread may submit during the call.
  void set_change_hook(ChangeHook hook, bool report_destroyed = false);

  // Returns when no operation is pending: every one submitted before the call
  // is done (and those other threads submit meanwhile, so a producer that
  // never pauses keeps it waiting). Then rethrows the first exception a
  // callback, hook or resumed coroutine threw since the last drain(), if any.
  // Throws pdt::Error(invalid_argument) when called from this engine's own
  // callbacks or from a coroutine it resumed: there it would wait for itself.
  void drain();
  // Operations submitted and not finished yet (for back-pressure).
  std::uint64_t in_flight() const;
  EngineStats stats() const;
  unsigned workers() const;
  [[deprecated("use workers(): it counts workers, not threads")]] unsigned threads() const { return workers(); }
  unsigned blocks_per_axis() const;
  const EngineOptions& options() const;

 private:
  friend struct detail::OpAwaitBase;
  std::unique_ptr<detail::EngineState> state_;
};

}  // namespace pdt
