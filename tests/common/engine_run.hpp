// SPDX-License-Identifier: MIT
#pragma once
// Running streams on an Engine in the tests: sizes scaled for TSan, a
// livelock watchdog, replaying a stream with the error sink, checking the
// result against the sequential replay and CGAL, the statistics' bookkeeping,
// and small coroutine and environment helpers.
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <coroutine>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <catch2/catch.hpp>

#include "common/cgal_reference.hpp"
#include "common/streams.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"

namespace pdt_test {

// -- sizes ---------------------------------------------------------------------
#if defined(__SANITIZE_THREAD__)
constexpr bool kTsan = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
constexpr bool kTsan = true;
#else
constexpr bool kTsan = false;
#endif
#else
constexpr bool kTsan = false;
#endif

// n in an optimised build; about a fifth of it (at least `floor`) under TSan,
// which is 5-15x slower and serialises more.
inline std::size_t scaled(std::size_t n, std::size_t floor = 200) { return kTsan ? std::max(floor, n / 5) : n; }

constexpr unsigned kThreadCounts[] = {1, 2, 4, 8, 16};
constexpr pdt::Distribution kDistributions[] = {pdt::Distribution::uniform, pdt::Distribution::normal,
                                                pdt::Distribution::line, pdt::Distribution::grid,
                                                pdt::Distribution::sphere};

// Collects the errors operations report through their callbacks (none is expected:
// a valid stream's operations cannot fail).
struct ErrorSink {
  std::atomic<std::uint64_t> count{0};
  std::mutex mutex;
  std::string first;
  pdt::Engine::Callback callback() {
    return [this](const pdt::OpResult& r) {
      if (!r.error) return;
      if (count.fetch_add(1) == 0) {
        std::string what = "unknown exception";
        try {
          std::rethrow_exception(r.error);
        } catch (const std::exception& e) {
          what = e.what();
        } catch (...) {
        }
        std::lock_guard lock(mutex);
        first = what;
      }
    };
  }
  void require_none() {
    std::lock_guard lock(mutex);
    INFO("operations failed: " << count.load() << ", the first with: " << first);
    REQUIRE(count.load() == 0);
  }
};

// Livelock and deadlock detector: while alive, polls the engine's statistics;
// if operations are pending (in_flight() > 0) but none completes for `limit`
// seconds, prints the statistics and aborts, so the run fails with a
// diagnosis instead of hanging until an outer timeout. Workers that keep
// attempting are a livelock (a lock that is never released makes every
// operation touching it roll back forever); workers that attempt nothing
// while work is pending are a deadlock (a worker waiting for one that never
// runs). No pending operation is idle, however long.
class Watchdog {
 public:
  Watchdog(const pdt::Engine& e, std::string label) : engine_(e), label_(std::move(label)), thread_([this] { run(); }) {}
  ~Watchdog() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  void run() {
    const double limit = kTsan ? 300 : 60;
    std::uint64_t completed = 0, attempts_then = 0;
    auto last_progress = std::chrono::steady_clock::now();
    std::unique_lock lock(mutex_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(500), [this] { return stop_; })) {
      const std::uint64_t pending = engine_.in_flight();
      const pdt::WorkerStats t = engine_.stats().total();
      const auto now = std::chrono::steady_clock::now();
      if (t.completed != completed || pending == 0) {  // progress, or idle
        last_progress = now;
        attempts_then = t.attempts;
      }
      completed = t.completed;
      if (std::chrono::duration<double>(now - last_progress).count() > limit) {
        const std::uint64_t attempts = t.attempts - attempts_then;
        std::fprintf(stderr,
                     "\n[engine watchdog] %s: %s: %llu operations pending, %llu attempts, none completed for %.0f s "
                     "(completed %llu, rollbacks %llu, deferred %llu, sleeps %llu); aborting\n",
                     label_.c_str(), attempts == 0 ? "deadlock" : "livelock", static_cast<unsigned long long>(pending),
                     static_cast<unsigned long long>(attempts), limit, static_cast<unsigned long long>(t.completed),
                     static_cast<unsigned long long>(t.rollbacks), static_cast<unsigned long long>(t.deferred),
                     static_cast<unsigned long long>(t.sleeps));
        std::fflush(stderr);
        std::abort();
      }
    }
  }
  const pdt::Engine& engine_;
  std::string label_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;  // last: started once the rest is ready
};

// Submits a stream to an engine: ticket k must be insertion k.
inline void submit_stream(pdt::Engine& e, const pdt::OpStream& s, std::vector<pdt::Engine::Ticket>& tickets,
                   ErrorSink& errors) {
  for (const auto& op : s.ops) {
    if (op.kind == pdt::Operation::Kind::insert) {
      const pdt::Engine::Ticket t = e.insert(op.point, errors.callback());
      if (t != tickets.size()) FAIL("ticket " << t << " for insertion " << tickets.size());
      tickets.push_back(t);
    } else {
      e.remove_insertion(tickets.at(op.target), errors.callback());
    }
  }
}

enum class ArenaMode {
  inside,       // Engine constructed and used inside arena.execute, no arena argument
  passed,       // Engine constructed on the test thread with &arena
  caller_default  // no explicit arena at all: the caller's (implicit) one
};

struct EngineRun {
  pdt::EngineStats stats;
  pdt::EngineStats stats_at_barrier;  // when drained after `barrier` operations
  unsigned threads = 0;
  unsigned blocks = 0;
};

inline pdt::EngineOptions options_with(unsigned threads) {
  pdt::EngineOptions o;  // not from the environment: the test decides
  o.workers = threads;
  o.grid_slots = 1u << 18;
  return o;
}

// Replays s on an engine; with a barrier, drains after the first `barrier`
// operations (the rest of the stream then runs against that state).
inline EngineRun replay_engine(pdt::Triangulation& t, const pdt::OpStream& s, const pdt::Box& box, pdt::EngineOptions o,
                        ArenaMode mode = ArenaMode::inside, int arena_concurrency = 2, std::size_t barrier = 0) {
  EngineRun run;
  ErrorSink errors;
  auto body = [&](tbb::task_arena* arena) {
    pdt::Engine e(t, box, o, arena);
    Watchdog watchdog(e, std::to_string(s.ops.size()) + " operations, " + std::to_string(o.workers) + " workers");
    std::vector<pdt::Engine::Ticket> tickets;
    if (barrier) {
      pdt::OpStream head, tail;
      head.ops.assign(s.ops.begin(), s.ops.begin() + static_cast<std::ptrdiff_t>(barrier));
      tail.ops.assign(s.ops.begin() + static_cast<std::ptrdiff_t>(barrier), s.ops.end());
      submit_stream(e, head, tickets, errors);
      e.drain();
      run.stats_at_barrier = e.stats();
      submit_stream(e, tail, tickets, errors);
    } else {
      submit_stream(e, s, tickets, errors);
    }
    e.drain();
    run.stats = e.stats();
    run.threads = e.workers();
    run.blocks = e.blocks_per_axis();
  };
  if (mode == ArenaMode::caller_default) {
    body(nullptr);
  } else {
    tbb::task_arena arena(arena_concurrency);
    if (mode == ArenaMode::inside)
      arena.execute([&] { body(nullptr); });
    else
      body(&arena);
  }
  errors.require_none();
  return run;
}

inline std::uint64_t total_multiplicity(const pdt::Triangulation& t) {
  std::uint64_t m = 0;
  for (pdt::VertexId v : t.vertices()) m += t.multiplicity(v);
  return m;
}

// Valid, CGAL's triangulation of the stream's survivors (multiplicities
// included), and, when given, tetrahedron for tetrahedron the sequential result.
inline void require_result(const pdt::Triangulation& t, const pdt::OpStream& s, const pdt::Triangulation* seq = nullptr) {
  require_valid(t);
  const std::vector<pdt::Point3> surv = survivors(s);
  require_same_as_cgal(t, surv);
  REQUIRE(total_multiplicity(t) == surv.size());
  if (seq) {
    const PointIndex idx = make_point_index(surv);
    REQUIRE(t.dimension() == seq->dimension());
    REQUIRE(t.number_of_vertices() == seq->number_of_vertices());
    REQUIRE(t.number_of_cells() == seq->number_of_cells());
    const bool same = canonical_tets(t, idx) == canonical_tets(*seq, idx);
    REQUIRE(same);
  }
}

// The bookkeeping the engine documents: every operation completed once; every
// attempt either completed or rolled back (a deferred undo is no attempt).
inline void require_stats(const EngineRun& run, std::size_t operations, unsigned threads) {
  const pdt::EngineStats& st = run.stats;
  REQUIRE(st.workers.size() == threads);
  std::uint64_t completed = 0;
  for (const pdt::WorkerStats& w : st.workers) {
    INFO("completed " << w.completed << " attempts " << w.attempts << " rollbacks " << w.rollbacks << " deferred "
                      << w.deferred);
    REQUIRE(w.attempts >= w.completed);
    REQUIRE(w.attempts == w.completed + w.rollbacks);
    REQUIRE(w.escalated <= w.completed);
    REQUIRE(w.seconds_asleep >= 0);
    completed += w.completed;
  }
  REQUIRE(completed == operations);
  const pdt::WorkerStats total = st.total();
  REQUIRE(total.completed == operations);
  REQUIRE(total.attempts >= total.completed);
}

template <class F>
inline std::optional<pdt::ErrorCode> error_of(F&& f, std::string* message = nullptr) {
  try {
    f();
  } catch (const pdt::Error& e) {
    if (message) *message = e.what();
    return e.code();
  }
  return std::nullopt;
}


// Sets environment variables for its lifetime; restores (unsets) them after.
struct EnvGuard {
  std::vector<std::string> names;
  void set(const char* name, const char* value) {
    ::setenv(name, value, 1);
    names.emplace_back(name);
  }
  ~EnvGuard() {
    for (const auto& n : names) ::unsetenv(n.c_str());
  }
};

// -- a minimal coroutine type: eager, self-destroying, no result --------------
struct Detached {
  struct promise_type {
    Detached get_return_object() noexcept { return {}; }
    std::suspend_never initial_suspend() noexcept { return {}; }
    std::suspend_never final_suspend() noexcept { return {}; }
    void return_void() noexcept {}
    void unhandled_exception() noexcept { std::terminate(); }  // bodies catch everything
  };
};

// Waits (draining) until `cond` holds or `seconds` pass.
template <class Cond>
inline bool wait_for(pdt::Engine& e, Cond cond, double seconds = 60) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!cond()) {
    if (std::chrono::steady_clock::now() > until) return false;
    e.drain();
    std::this_thread::yield();
  }
  return true;
}

}  // namespace pdt_test
