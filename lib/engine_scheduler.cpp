// SPDX-License-Identifier: MIT
// The engine's scheduler: worker coroutines run as oneTBB tasks, claiming
// blocks (home first, then the nearest busy block elsewhere), their phases
// (running, idle, sleeping, waiting for the stopped world) and wake-ups.
#include <algorithm>
#include <cassert>
#include <thread>

#include "engine_state.hpp"
#include "spatial_order.hpp"  // brio_round: the rounds of a batch's order

namespace pdt::detail {

thread_local const EngineState* EngineState::running_engine = nullptr;
thread_local unsigned EngineState::ops_on_this_thread = 0;

void EngineState::spawn(std::coroutine_handle<> h) {
  auto task = [this, h] {
    if (ops_on_this_thread != 0) {  // taken by client code inside an operation: later, elsewhere
      spawn(h);
      return;
    }
    const EngineState* outer = running_engine;
    running_engine = this;
    try {
      h.resume();
    } catch (...) {
      // A client coroutine whose promise rethrows: its exception must not
      // reach the task group (it would cancel the engine's other tasks).
      record_client_error(std::current_exception());
    }
    running_engine = outer;
  };
  // Enqueued into the engine's arena, from any thread: it never waits (with
  // arena->execute() a submitter waited for a free slot in a full arena, that
  // is for a worker thread, so one holding a lock that a hook or callback
  // takes deadlocked), and it lands in the engine's arena even from one of
  // its own tasks that entered another arena (a callback's execute()), where
  // tasks.run() would spawn it. The deferred task counts in `tasks` from now
  // on, so drain() waits for it.
  arena->enqueue(tasks.defer(std::move(task)));
}

// ---------------------------------------------------------------------------
// Phases: the awaiters that suspend a worker
// ---------------------------------------------------------------------------
namespace {

// What suspending a worker starts with: its count deltas folded into the
// totals (so counts are exact whenever nobody runs), and where to resume it.
struct WorkerAwait {
  EngineState* e;
  Worker* w;
  bool await_ready() const noexcept { return false; }
  void await_resume() const noexcept {}
  void prepare(std::coroutine_handle<> h) const {
    e->impl.fold_counters(*w->ctx);
    w->handle = h;
  }
};

struct IdleAwait : WorkerAwait {
  bool await_suspend(std::coroutine_handle<> h) {
    prepare(h);
    // Once `phase` says idle, a submitter may resume us on another thread:
    // from then on touch only locals (not this awaiter, which lives in the frame).
    EngineState* es = e;
    Worker* wk = w;
    wk->phase.store(WorkerPhase::idle, std::memory_order_seq_cst);
    es->idle_count.fetch_add(1, std::memory_order_seq_cst);
    es->active.fetch_sub(1, std::memory_order_seq_cst);
    es->wake_one();  // an idle worker competes with nobody: let a sleeper run
    // Work that arrived before we said idle, and whose submitter saw us
    // running: look once more (the submitter resumes us after this point).
    // Our `phase` store and work_for's `queued` loads are seq_cst (a store
    // then a load: the submitter does the mirror image, `queued` then
    // `phase`, both seq_cst), so one of the two sees the other.
    if (es->work_for(*wk)) {
      WorkerPhase expect = WorkerPhase::idle;
      // Resume as a new task, not by returning false: a submitter may have
      // resumed and re-suspended this coroutine already, so only the handle is ours.
      if (wk->phase.compare_exchange_strong(expect, WorkerPhase::running)) {
        es->idle_count.fetch_sub(1, std::memory_order_seq_cst);
        es->resume(*wk);
      }
    }
    return true;
  }
};

struct SleepAwait : WorkerAwait {
  bool await_suspend(std::coroutine_handle<> h) {
    prepare(h);
    EngineState* es = e;
    Worker* wk = w;
    std::lock_guard lock(es->sleep_mutex);
    if (es->active.load() <= 1) return false;  // the last running worker never sleeps
    wk->slept_at = std::chrono::steady_clock::now();
    wk->sleeps.fetch_add(1, std::memory_order_relaxed);
    wk->phase.store(WorkerPhase::sleeping);
    es->active.fetch_sub(1);
    es->sleepers.push_back(wk);  // reserved for every worker: no allocation
    return true;
  }
};

// The world is stopped: wait, suspended, until restart() resumes us. The
// worker stays `running` (it resumes by itself), holding no block.
struct WorldAwait {
  EngineState* e;
  bool await_ready() const noexcept { return false; }
  bool await_suspend(std::coroutine_handle<> h) { return e->world.wait(h); }
  void await_resume() const noexcept {}
};

}  // namespace

// ---------------------------------------------------------------------------
// The worker's body
// ---------------------------------------------------------------------------
WorkerCoroutine EngineState::body(Worker& w) {
  w.end_idle(steady_ns());  // idle since the engine was made (EngineState's constructor)
  for (;;) {
    if (world.stopped()) {
      co_await WorldAwait{this};
      continue;
    }
    Block* b = claim(w);
    if (!b) {
      if (maybe_recut(w)) continue;
      w.begin_idle(steady_ns());
      co_await IdleAwait{{this, &w}};
      w.end_idle(steady_ns());  // resumed (on whichever thread): the stretch ends now
      continue;
    }
    bool sleep = false;
    OpRecord* run = nullptr;  // a run of an insert_batch in hand (not queued meanwhile)
    // A batch's order is BRIO's rounds, each along a curve, so a block's
    // queue holds a stretch of each round. Once this claim has served a run,
    // the worker moves on to its next block when the next run here belongs
    // to a later round: its blocks then get their rounds in turn, close to
    // the batch's own order, instead of each block filling up before the
    // next is started (measured: 5% more cells made and walk steps at 1M
    // points, 16% at 20k, 1 worker). Nor does a claim start with a later
    // round than the worker's last run, in one of its home blocks, until it
    // has made as many such claims in a row as its home has blocks: its
    // other blocks may still hold runs of its round (taking the later one
    // there made 0.4% more cells at 1M points, 1-3% at 4k-20k, 1 worker).
    bool took_run = false;
    for (std::uint32_t served = 0; served < batch && !sleep; ++served) {
      OpRecord* op = nullptr;
      if (!run) {
        op = b->queue.pop();
        if (!op) break;
        b->queued.fetch_sub(1, std::memory_order_relaxed);
        if (op->run_end) {
          const bool same_batch = reinterpret_cast<std::uintptr_t>(op->batch_done) == w.batch_taken;
          const std::size_t n = op->batch_done->point_count();
          const unsigned round = brio_round(op->run_next, n);  // 0: the last round
          const unsigned last = same_batch ? brio_round(w.batch_taken_end - 1, n) : round;
          const std::uint32_t home = partition.home_first(w.index + 1) - partition.home_first(w.index);
          if ((took_run && round != last) ||
              (!took_run && round < last && b->home == w.index && w.skipped < home)) {
            count_in_front(*b, op);  // a later round: after this worker's other blocks
            w.repeat = max_repeat;   // claim() starts at the next block
            if (!took_run) ++w.skipped;
            break;
          }
          w.skipped = 0;
          if (!same_batch || op->run_next != w.batch_taken_end) w.last_inserted = no_vertex;  // walk from the grid
          run = op;
          took_run = true;
        }
      }
      if (run) {
        op = take_from_run(w, run);
        if (!op) break;  // no record to be had now: the run waits in its block
      }
      const Outcome outcome = execute(w, op);
      if (outcome == Outcome::rollback || outcome == Outcome::global)
        count_in(*b, op);  // back of its block's queue: the others go first
      if (outcome == Outcome::global) break;  // the world is stopped: wait for it
      maybe_grow_grid(w);
      using Verdict = ContentionManager::Verdict;
      switch (w.contention.judge()) {
        case Verdict::sleep: sleep = true; break;
        case Verdict::wake_another: wake_one(); break;
        case Verdict::carry_on: break;
      }
    }
    publish_batch_done(w);
    if (run) count_in_front(*b, run);  // what is left of it, next in its block
    release(*b);
    // Work left behind while workers idle: let one take it (or another block
    // this worker then claims first). Without this, a worker that went idle
    // once every busy block was held would wait for the next submission,
    // which may never come when the stream is all submitted.
    if (opts.stealing && b->queued.load(std::memory_order_relaxed) != 0 &&
        idle_count.load(std::memory_order_relaxed) > 0)
      wake_idle();
    if (sleep) co_await SleepAwait{{this, &w}};
  }
}

OpRecord* EngineState::take_from_run(Worker& w, OpRecord*& run) {
  OpRecord* one = w.kept;
  if (one) {
    w.kept = one->next.load(std::memory_order_relaxed);
    --w.kept_count;
  } else {
    try {
      if (!w.spare) w.spare = records.acquire();
      one = records.acquire();
    } catch (const std::bad_alloc&) {
      std::swap(one, w.spare);  // the spare, if there is one
      if (!one) return nullptr;
    }
  }
  assert(run->run_next < run->run_end);
  const BatchCallback& batch = *run->batch_done;
  const std::uint32_t k = run->run_next++;
  w.batch_taken = reinterpret_cast<std::uintptr_t>(run->batch_done);
  w.batch_taken_end = k + 1;
  one->kind = OpKind::insert;
  one->from_batch = true;
  one->point = batch.points[k];
  one->ticket = batch.first_ticket + batch.index[k];
  TicketRange* range = batch.ticket_range;  // slot k if in run order (position), else by ticket
  one->ticket_range = range;
  one->ticket_slot = range->position ? k : range->slot_of(one->ticket);
  one->batch_done = run->batch_done;
  if (run->run_next == run->run_end) {
    records.release(run);
    run = nullptr;
  } else {
    run->point = batch.points[run->run_next];
  }
  return one;
}

// ---------------------------------------------------------------------------
// Claiming blocks
// ---------------------------------------------------------------------------
bool EngineState::may_serve(const Worker& w, const Block& b) const {
  // seq_cst: the idle worker's last look (IdleAwait) relies on it; on x86 a
  // plain load like acquire.
  return b.queued.load(std::memory_order_seq_cst) != 0 && b.holder.load(std::memory_order_relaxed) == -1 &&
         (opts.stealing || b.home == w.index);
}

Block* EngineState::claim(Worker& w) {
  auto try_claim = [&](std::uint32_t i) -> Block* {
    Block& b = blocks[i];
    if (!may_serve(w, b)) {
      if (b.queued.load(std::memory_order_relaxed) == 0) nonempty.clear_if_empty(i, b.queued);
      return nullptr;
    }
    int expect = -1;
    if (!b.holder.compare_exchange_strong(expect, static_cast<int>(w.index), std::memory_order_acq_rel)) return nullptr;
    if (b.queued.load(std::memory_order_acquire) == 0) {  // emptied meanwhile
      b.holder.store(-1, std::memory_order_release);
      return nullptr;
    }
    return &b;
  };
  const std::uint32_t first = partition.home_first(w.index), end = partition.home_first(w.index + 1);
  const std::uint32_t count = partition.blocks();
  // Elsewhere, nearest first along the curve (ties: the lower side first),
  // visiting only the blocks marked non-empty. Blocks whose home is not
  // running (asleep, idle, waiting) before busy homes' blocks.
  auto steal = [&](bool orphans_only) -> Block* {
    // Orphans (work whose home is not running) sit in sleepers' blocks (an
    // idle home is resumed by the submission that fills its block). With no
    // sleeper, skip the scan: it would look at every non-empty block only to
    // find each home running (with far more workers than threads, most of
    // the run's time). A sleeper that falls asleep meanwhile is found by the
    // next claim's look.
    if (orphans_only && static_cast<std::size_t>(active.load(std::memory_order_relaxed)) +
                                static_cast<std::size_t>(idle_count.load(std::memory_order_relaxed)) >=
                            workers.size())
      return nullptr;
    std::int64_t below = nonempty.prev(std::int64_t{first} - 1);
    std::uint32_t above = nonempty.next(end, count);
    while (below >= 0 || above < count) {
      const bool take_below = below >= 0 && (above >= count || std::int64_t{first} - below <=
                                                                   std::int64_t{above} - (std::int64_t{end} - 1));
      const std::uint32_t i = take_below ? static_cast<std::uint32_t>(below) : above;
      if (take_below)
        below = nonempty.prev(below - 1);
      else
        above = nonempty.next(above + 1, count);
      if (orphans_only && workers[blocks[i].home]->phase.load(std::memory_order_relaxed) == WorkerPhase::running)
        continue;
      if (Block* got = try_claim(i)) {
        w.steals.fetch_add(1, std::memory_order_relaxed);
        return got;
      }
    }
    return nullptr;
  };
  // Now and then, orphans first, so a sleeper's blocks are not left waiting
  // behind a home that always has work.
  if (opts.stealing && (++w.claims & 3) == 0)
    if (Block* b = steal(true)) return b;
  const std::uint32_t n = end - first;
  if (w.repeat >= max_repeat) {
    w.home_cursor = n ? (w.home_cursor + 1) % n : 0;
    w.repeat = 0;
  }
  // The home's blocks from the cursor on, round to it, visiting only those
  // marked non-empty (with one worker every block is home: reading each
  // block's count took 4% of a refinement, whose few operations in flight
  // make every operation a claim).
  auto home_run = [&](std::uint32_t from, std::uint32_t to) -> Block* {
    for (std::uint32_t i = nonempty.next(from, to); i < to; i = nonempty.next(i + 1, to))
      if (Block* b = try_claim(i)) {
        const std::uint32_t at = i - first;
        w.repeat = at == w.home_cursor ? w.repeat + 1 : 1;
        w.home_cursor = at;
        return b;
      }
    return nullptr;
  };
  if (n != 0) {
    assert(w.home_cursor < n);  // a recut moves the blocks' bounds, not the homes' runs
    if (Block* b = home_run(first + w.home_cursor, end)) return b;
    if (Block* b = home_run(first, first + w.home_cursor)) return b;
  }
  if (!opts.stealing) return nullptr;
  if (Block* b = steal(true)) return b;
  return steal(false);
}

bool EngineState::work_for(const Worker& w) const {
  // With stealing off, w serves its home alone (blocks[i].home == w exactly
  // for i in its home run: homes move only in a recut, which needs stealing).
  const std::uint32_t first = opts.stealing ? 0 : partition.home_first(w.index);
  const std::uint32_t end = opts.stealing ? partition.blocks() : partition.home_first(w.index + 1);
  for (std::uint32_t i = nonempty.next(first, end); i < end; i = nonempty.next(i + 1, end))
    if (may_serve(w, blocks[i])) return true;
  return false;
}

void EngineState::release(Block& b) {
  assert(b.holder.load(std::memory_order_relaxed) >= 0);
  b.holder.store(-1, std::memory_order_release);
}

// ---------------------------------------------------------------------------
// Rebalancing: re-cutting the blocks where the work is
// ---------------------------------------------------------------------------
std::uint64_t EngineState::completed_total() const {
  std::uint64_t n = 0;
  for (const auto& w : workers) n += w->completed.load(std::memory_order_relaxed);
  return n;
}

bool EngineState::maybe_recut(Worker& w) {
  if (!opts.stealing || !opts.rebalance || nworkers < 2 || world.stopped()) return false;
  const std::uint32_t count = partition.blocks();
  // claim() found nothing, so the pending work is in blocks that others
  // serve (or in their hands, or waiting on a ticket). Counted in operations:
  // a run of a batch is one record but many points.
  const std::uint64_t pending = in_flight();
  if (pending < recut_min_pending * nworkers || completed_total() < recut_after.load(std::memory_order_relaxed))
    return false;
  std::unique_lock<std::mutex> lock;
  if (!world.try_stop(w.index, lock)) return false;
  // Claim every block. A holder lets go within one operation (it finds the
  // world stopped); one that does not within the deadline (a client callback
  // that blocks) cancels this recut.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(20);
  std::uint32_t claimed = 0;
  for (; claimed < count; ++claimed) {
    bool got = false;
    for (;;) {
      int expect = -1;
      got = blocks[claimed].holder.compare_exchange_weak(expect, static_cast<int>(w.index), std::memory_order_acq_rel);
      if (got || std::chrono::steady_clock::now() > deadline) break;
      std::this_thread::yield();
    }
    if (!got) break;
  }
  bool recut = false;
  if (claimed == count) {
#ifndef NDEBUG
    // NonEmptyBlocks' invariant: every block holding work is marked (a
    // submitter between its count and its mark finishes at once).
    for (std::uint32_t i = 0; i < count; ++i) {
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);  // a descheduled submitter
      while (blocks[i].queued.load() != 0 && !nonempty.marked(i) && std::chrono::steady_clock::now() < until)
        std::this_thread::yield();
      assert(blocks[i].queued.load() == 0 || nonempty.marked(i));
    }
#endif
    // Every queued record out, chained in order through its (now free) queue
    // link, and how many operations they stand for (a run: its points left).
    OpRecord* first = nullptr;
    OpRecord* last = nullptr;
    std::uint64_t weight = 0;
    auto weight_of = [](const OpRecord* op) -> std::uint64_t { return op->run_end ? op->run_end - op->run_next : 1; };
    for (std::uint32_t i = 0; i < count; ++i) {
      Block& b = blocks[i];
      while (OpRecord* op = b.queue.pop()) {
        b.queued.fetch_sub(1, std::memory_order_relaxed);
        op->next.store(nullptr, std::memory_order_relaxed);
        if (last)
          last->next.store(op, std::memory_order_relaxed);
        else
          first = op;
        last = op;
        if (op->routed) weight += weight_of(op);
      }
    }
    // A sample of their keys, every stride-th operation (within capacity: no
    // allocation), and the cut at its quantiles.
    recut_keys.clear();
    const std::uint64_t stride = std::max<std::uint64_t>(1, (weight + recut_keys.capacity() - 1) /
                                                                std::max<std::size_t>(1, recut_keys.capacity()));
    std::uint64_t seen = 0;
    for (OpRecord* op = first; op; op = op->next.load(std::memory_order_relaxed)) {
      if (!op->routed) continue;
      const std::uint64_t key = partition.key_of(op->point);
      const std::uint64_t next = seen + weight_of(op);
      for (std::uint64_t at = (seen + stride - 1) / stride * stride; at < next; at += stride)
        if (recut_keys.size() < recut_keys.capacity()) recut_keys.push_back(key);
      seen = next;
    }
    if (!recut_keys.empty()) {
      std::sort(recut_keys.begin(), recut_keys.end());
      partition.recut(recut_keys);
      recut = true;
    }
    // Back in, each to its block under the new cut, in their old order.
    while (first) {
      OpRecord* op = first;
      first = op->next.load(std::memory_order_relaxed);
      const std::uint32_t dest = op->routed ? partition.block_of(op->point)
                                            : static_cast<std::uint32_t>(
                                                  (op->vertex != no_vertex ? op->vertex : op->ticket) % count);
      count_in(blocks[dest], op);
    }
    recut_after.store(completed_total() + weight / 2, std::memory_order_relaxed);
    if (recut) recuts.fetch_add(1, std::memory_order_relaxed);
  } else {
    recut_after.store(completed_total() + pending / 2, std::memory_order_relaxed);
  }
  for (std::uint32_t i = 0; i < claimed; ++i) blocks[i].holder.store(-1, std::memory_order_release);
  world.restart(lock, [this](std::coroutine_handle<> h) { spawn(h); });
  // The work is spread now: let the idle workers at it.
  for (unsigned k = 0; k < nworkers && idle_count.load(std::memory_order_seq_cst) > 0; ++k)
    if (!wake_idle()) break;
  return recut;
}

// ---------------------------------------------------------------------------
// Wake-ups
// ---------------------------------------------------------------------------
void EngineState::resume(Worker& w) {
  active.fetch_add(1, std::memory_order_seq_cst);
  spawn(w.handle);
}

void EngineState::count_in(Block& b, OpRecord* op) {
  b.queued.fetch_add(1, std::memory_order_seq_cst);
  nonempty.mark(index_of(b));
  b.queue.push(op);
}

void EngineState::count_in_front(Block& b, OpRecord* op) {
  assert(b.holder.load(std::memory_order_relaxed) >= 0);  // the consumer's side of the queue
  b.queued.fetch_add(1, std::memory_order_seq_cst);
  nonempty.mark(index_of(b));
  b.queue.push_front(op);
}

void EngineState::enqueue(Block& b, OpRecord* op) {
  count_in(b, op);
  Worker& home = *workers[b.home];
  // Looked at before the exchange, which would take the line for writing on
  // every submission: a seq_cst load orders against count_in's seq_cst
  // writes as a failed exchange would.
  WorkerPhase expect = home.phase.load(std::memory_order_seq_cst);
  if (expect == WorkerPhase::idle && home.phase.compare_exchange_strong(expect, WorkerPhase::running)) {
    idle_count.fetch_sub(1, std::memory_order_seq_cst);
    resume(home);
    return;
  }
  // The home is busy (or asleep): an idle worker may take this block over
  // once it holds a few operations. (The block's count first: its line is
  // here already; idle_count's is written by every worker going idle.)
  if (opts.stealing && (expect != WorkerPhase::running || b.queued.load(std::memory_order_relaxed) >= 8) &&
      idle_count.load(std::memory_order_seq_cst) > 0 && wake_idle())
    return;
  if (expect == WorkerPhase::sleeping && active.load(std::memory_order_seq_cst) == 0) {
    // Nobody runs to wake it: do it here.
    std::unique_lock lock(sleep_mutex);
    if (std::find(sleepers.begin(), sleepers.end(), &home) == sleepers.end()) return;
    wake_locked(home);
    lock.unlock();
    resume(home);
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

bool EngineState::wake_idle() {
  for (auto& w : workers) {
    WorkerPhase expect = WorkerPhase::idle;
    if (w->phase.load(std::memory_order_relaxed) == WorkerPhase::idle &&
        w->phase.compare_exchange_strong(expect, WorkerPhase::running)) {
      idle_count.fetch_sub(1, std::memory_order_seq_cst);
      resume(*w);
      return true;
    }
  }
  return false;
}

std::uint64_t EngineState::in_flight() const {
  // finished is read before submitted: finished never exceeds submitted, so
  // the difference is never negative, and 0 means that when the finished
  // counts were read, everything submitted until then was done.
  std::uint64_t finished = 0, submitted = 0;
  for (const auto& w : workers) finished += w->finished.load(std::memory_order_acquire);
  for (std::uint32_t i = 0; i < submit_shards; ++i) submitted += this->submitted[i].n.load(std::memory_order_acquire);
  assert(finished <= submitted);
  return submitted - finished;
}

bool EngineState::idle_everywhere() const { return in_flight() == 0; }

// ---------------------------------------------------------------------------
// The jump grid's growth, with the world stopped
// ---------------------------------------------------------------------------
void EngineState::ensure_grid(bool parallel, bool follow, bool shrunk) {
  if (impl.dim.load() < 3) return;  // no grid below dimension 3
  const std::size_t ids = impl.vertex_ids_in_use();  // not the id bound: shrink_to_fit may have given ids back
  const auto live = static_cast<std::size_t>(std::max<std::int64_t>(0, impl.n_vertices.load()));
  if (shrunk) {
    if (!impl.grid.shrunk_since_build(live)) return;  // another worker's rebuild came first
  } else if (follow) {
    if (!impl.grid.grown_since_build(live)) return;  // another worker's rebuild came first
  } else if (impl.grid.slot_count && ids < grid_grow_at.load(std::memory_order_relaxed)) {
    return;
  }
  // Over the live vertices' bounding box, about two vertices per slot: the
  // ids handed out stand for them as the mesh grows (the live count lags
  // while workers hold deltas), the live count once removals shrank it.
  const std::size_t most = std::max<std::size_t>(opts.grid_slots, 1);
  const std::size_t slots = std::clamp<std::size_t>((shrunk ? live : ids) / 2, 1, most);
  impl.grid_rebuild(slots, parallel, most, grid_follows || follow);
  if (follow) grid_follows = true;  // after the rebuild: a failed one changes nothing
  grid_grow_at.store(2 * ids + 1024, std::memory_order_relaxed);
  grid_built_for.store(impl.grid.built_for, std::memory_order_relaxed);
  if (!follow || shrunk) grid_doublings.fetch_add(1, std::memory_order_relaxed);  // re-arms the workers' watches
  // A grid at the cap may not get finer: walks long then are not its age.
  grid_may_grow.store(slots < most, std::memory_order_relaxed);
}

void EngineState::maybe_grow_grid(Worker& w) {
  // Below dimension 3 there is no grid; the global step that builds the
  // tetrahedra sizes it (run_global calls ensure_grid).
  if (impl.dim.load(std::memory_order_relaxed) < 3) return;
  const bool grow = impl.vertex_ids_in_use() >= grid_grow_at.load(std::memory_order_relaxed);
  // Only atomics here: outside the stopped world, another worker may be
  // replacing the grid.
  const std::uint32_t doublings = grid_doublings.load(std::memory_order_relaxed);
  if (w.walks_doublings != doublings) w.walks.rearm(), w.walks_doublings = doublings;
  const auto live = static_cast<std::size_t>(std::max<std::int64_t>(0, impl.n_vertices.load()));
  const std::size_t built_for = grid_built_for.load(std::memory_order_relaxed);
  // Removals left a quarter of the vertices the grid was built for: its
  // slots name mostly dead vertices (Impl::grid_note_removal says why).
  const bool shrunk = !grow && JumpGrid::shrunk_since(built_for, live);
  const bool follow = !grow && !shrunk && grid_may_grow.load(std::memory_order_relaxed) &&
                      JumpGrid::grown_since(built_for, live) &&
                      w.walks.long_walks(w.ctx->stats.walk_steps, w.ctx->stats.insertions);
  if (!grow && !follow && !shrunk) return;
  std::unique_lock<std::mutex> lock;
  if (!world.try_stop(w.index, lock)) return;  // another worker is in a global step; it checks too
  try {
    ensure_grid(true, follow, shrunk);  // on this worker's thread and the suspended workers' (their threads are free)
  } catch (const std::bad_alloc&) {
    // The old grid stays (it was built aside); walks are longer, nothing is
    // wrong. Not tried again until the ids double or the live count moves
    // a quarter from here.
    grid_grow_at.store(2 * impl.vertex_ids_in_use() + 1024, std::memory_order_relaxed);
    grid_built_for.store(live, std::memory_order_relaxed);
  }
  world.restart(lock, [this](std::coroutine_handle<> h) { spawn(h); });
}

}  // namespace pdt::detail
