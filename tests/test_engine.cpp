// SPDX-License-Identifier: MIT
// The parallel engine (pdt::Engine): many workers on one Triangulation give
// exactly the sequential / CGAL result for any stream, thread count and
// interleaving; the coroutine and callback APIs; errors at submission; the
// options and their environment mirrors; the contention manager; the
// triangulation stays usable after the engine is gone.
//
// Sizes shrink under ThreadSanitizer (see scaled()): the [tsan] cases are the
// ones meant to be run in the TSan build, e.g.
//   TSAN_OPTIONS=halt_on_error=0 ./build-tsan/tests/pdt_tests "[engine]"
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <coroutine>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/point_sets.hpp"
#include "common/streams.hpp"
#include "common/engine_run.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"
#include "nonempty_blocks.hpp"     // the claim scan's bitmap, tested alone
#include "spatial_order.hpp"       // the order an engine's insert_batch follows
#include "partition.hpp"           // the recut test reads the blocks' cut
#include "triangulation_impl.hpp"  // the contention test holds a vertex lock itself

using namespace pdt_test;
using pdt::Point3;

namespace {

std::vector<Point3> data_subsample(const std::string& rel, std::size_t n, std::uint64_t seed) {
  const std::string path = shared_data(rel);
  if (!std::filesystem::exists(path)) return {};
  std::vector<Point3> pts = pdt::read_points(path);
  shuffle(pts, seed);
  if (pts.size() > n) pts.resize(n);
  return pts;
}

// What coroutines running on worker threads report (Catch2 assertions are not
// thread-safe, so they record here and the test thread checks).
struct Tally {
  std::atomic<int> finished{0};
  std::mutex mutex;
  std::vector<std::string> failures;
  std::vector<Point3> kept;  // points left in the triangulation (with repetitions)
  void fail(const std::string& s) {
    std::lock_guard lock(mutex);
    failures.push_back(s);
  }
  void keep(const Point3& p) {
    std::lock_guard lock(mutex);
    kept.push_back(p);
  }
};

std::string failures_text(Tally& tally) {
  std::lock_guard lock(tally.mutex);
  std::string s;
  for (std::size_t i = 0; i < tally.failures.size() && i < 10; ++i) s += tally.failures[i] + "\n";
  return s;
}

// Inserts its points one by one with co_await; removes every third at once,
// inserts every fifth twice (a duplicate) and undoes the second insertion.
Detached churn(pdt::Engine& engine, std::vector<Point3> pts, Tally& tally) {
  try {
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Point3 p = pts[i];
      pdt::InsertResult r = co_await engine.insert(p);
      if (!r.inserted || r.vertex == pdt::no_vertex || r.vertex == pdt::infinite_vertex) {
        tally.fail("insert " + str(p) + ": inserted=" + std::to_string(r.inserted) + " vertex=" +
                   std::to_string(r.vertex));
        continue;
      }
      if (i % 5 == 0) {
        pdt::InsertResult again = co_await engine.insert(p);
        if (again.inserted || again.vertex != r.vertex)
          tally.fail("duplicate " + str(p) + ": inserted=" + std::to_string(again.inserted) + " vertex " +
                     std::to_string(again.vertex) + " vs " + std::to_string(r.vertex));
        pdt::RemoveResult lowered = co_await engine.remove(r.vertex);
        if (lowered != pdt::RemoveResult::multiplicity_lowered) tally.fail("duplicate removal " + str(p));
      }
      if (i % 3 == 0) {
        pdt::RemoveResult rr = co_await engine.remove(r.vertex);
        if (rr != pdt::RemoveResult::removed) tally.fail("remove " + str(p) + " did not remove");
      } else {
        tally.keep(p);
      }
    }
  } catch (const std::exception& e) {
    tally.fail(std::string("exception: ") + e.what());
  }
  tally.finished.fetch_add(1);
}

// Runs one awaited operation and records the pdt::Error code it threw, if any.
struct AwaitOutcome {
  std::atomic<bool> done{false};  // set last (release): code and message are written before
  std::optional<pdt::ErrorCode> code;
  std::string message;
};

Detached await_insert(pdt::Engine& engine, Point3 p, AwaitOutcome& out) {
  try {
    (void)co_await engine.insert(p);
  } catch (const pdt::Error& e) {
    out.code = e.code();
    out.message = e.what();
  }
  out.done.store(true);
}

Detached await_remove(pdt::Engine& engine, pdt::VertexId v, AwaitOutcome& out) {
  try {
    (void)co_await engine.remove(v);
  } catch (const pdt::Error& e) {
    out.code = e.code();
    out.message = e.what();
  }
  out.done.store(true);
}

Detached insert_then_remove(pdt::Engine& engine, Point3 p, std::atomic<pdt::VertexId>& vertex,
                            std::atomic<int>& state) {
  pdt::InsertResult r = co_await engine.insert(p);
  vertex.store(r.vertex);
  co_await engine.remove(r.vertex);
  state.store(1);
}

}  // namespace

// =============================================================================
// 1. Correct under concurrency
// =============================================================================
TEST_CASE("engine: every distribution and thread count gives the sequential and CGAL result", "[engine][tsan]") {
  const std::size_t n = scaled(3000, 400);
  for (pdt::Distribution dist : kDistributions) {
    const pdt::OpStream s = generated(dist, n, 0.3, pdt::RemovalOrder::interleaved, 11);
    REQUIRE(s.box.has_value());
    pdt::Triangulation seq;
    replay_sequential(seq, s);
    for (unsigned threads : kThreadCounts) {
      // Every thread count inside arena.execute; 4 and 16 also with the arena passed.
      std::vector<ArenaMode> modes{ArenaMode::inside};
      if (threads == 4 || threads == 16) modes.push_back(ArenaMode::passed);
      for (ArenaMode mode : modes) {
        INFO("distribution " << pdt::to_string(dist) << ", " << n << " points, " << threads << " workers, arena "
                             << (mode == ArenaMode::inside ? "execute" : "passed"));
        pdt::Triangulation t;
        const EngineRun run = replay_engine(t, s, *s.box, options_with(threads), mode);
        REQUIRE(run.threads == threads);
        require_stats(run, s.ops.size(), threads);
        REQUIRE(run.stats.global_operations > 0);  // the first points (dimension < 3)
        require_result(t, s, &seq);
      }
    }
  }
}

TEST_CASE("engine: repeated streams with removals lose no operation", "[engine][stress]") {
  // Many short runs: races between a removal and an insertion next door show
  // up as a failed operation (reported through its callback), an extra or
  // missing vertex, or a livelock (the watchdog aborts).
  const int rounds = kTsan ? 4 : 24;
  for (int r = 0; r < rounds; ++r) {
    const pdt::Distribution dist = r % 3 == 0 ? pdt::Distribution::normal : pdt::Distribution::uniform;
    const pdt::OpStream s = generated(dist, scaled(4000, 500), 0.5, pdt::RemovalOrder::interleaved, 500 + r);
    const unsigned threads = r % 2 ? 16 : 2;
    INFO("round " << r << ", " << pdt::to_string(dist) << ", " << threads << " workers, seed " << 500 + r);
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(threads));
    require_stats(run, s.ops.size(), threads);
    REQUIRE(t.number_of_vertices() == s.insert_count() - s.remove_count());
    require_valid(t);
    if (r % 6 == 0) require_result(t, s);
  }
}

TEST_CASE("engine: with threads = 0 the workers follow the arena's concurrency", "[engine]") {
  const pdt::OpStream s = generated(pdt::Distribution::uniform, scaled(2000), 0.3, pdt::RemovalOrder::interleaved, 3);
  for (int conc : {1, 2}) {
    INFO("arena concurrency " << conc);
    pdt::Triangulation t;
    pdt::EngineOptions o = options_with(0);
    const EngineRun run = replay_engine(t, s, *s.box, o, ArenaMode::inside, conc);
    REQUIRE(run.threads == static_cast<unsigned>(conc));
    unsigned b = 1;
    while (b * b * b < std::max(512u, 64 * run.threads)) ++b;  // EngineOptions::blocks_per_axis
    REQUIRE(run.blocks == b);
    require_stats(run, s.ops.size(), run.threads);
    require_result(t, s);
  }
  {
    INFO("no arena at all: the caller's default arena");
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(0), ArenaMode::caller_default);
    REQUIRE(run.threads == static_cast<unsigned>(std::max(1, tbb::this_task_arena::max_concurrency())));
    require_stats(run, s.ops.size(), run.threads);
    require_result(t, s);
  }
}

TEST_CASE("engine: real point sets give CGAL's triangulation", "[engine][data][tsan]") {
  struct Set {
    const char* rel;
    std::size_t n;
  };
  const Set sets[] = {{"scans/cgal_b9.ply", 12000}, {"degenerate/cgal_radar.xyz", 12000},
                      {"scans/stanford_bunny_bun000.ply", 12000}};
  for (const Set& set : sets) {
    const std::size_t n = scaled(set.n, 1000);
    std::vector<Point3> pts = data_subsample(set.rel, n, 2024);
    if (pts.empty()) {
      WARN("data file absent, skipped: " << shared_data(set.rel));
      continue;
    }
    REQUIRE(pts.size() == n);
    const pdt::OpStream s = stream_of(pts, 0.3, 99);
    pdt::Triangulation seq;
    replay_sequential(seq, s);
    for (unsigned threads : {2u, 16u}) {
      INFO(set.rel << ": " << pts.size() << " points, " << threads << " workers");
      pdt::Triangulation t;
      const EngineRun run = replay_engine(t, s, *s.box, options_with(threads),
                                          threads == 16 ? ArenaMode::passed : ArenaMode::inside);
      require_stats(run, s.ops.size(), threads);
      require_result(t, s, &seq);
    }
  }
}

TEST_CASE("engine: integer lattice and exact cospherical points, removals after", "[engine][tsan]") {
  // The lattice: masses of cospherical and coplanar subsets; the sphere: all
  // points cospherical. Removal of half of them after all insertions.
  for (pdt::Distribution dist : {pdt::Distribution::grid, pdt::Distribution::sphere}) {
    const pdt::OpStream s = generated(dist, scaled(2500, 400), 0.5, pdt::RemovalOrder::after, 5);
    pdt::Triangulation seq;
    replay_sequential(seq, s);
    for (unsigned threads : {3u, 16u}) {
      INFO(pdt::to_string(dist) << ", " << threads << " workers");
      pdt::Triangulation t;
      const EngineRun run = replay_engine(t, s, *s.box, options_with(threads));
      require_stats(run, s.ops.size(), threads);
      require_result(t, s, &seq);
    }
  }
}

TEST_CASE("engine: the centre of 510 cospherical points removed, its link put in spatial order", "[engine][tsan]") {
  // The centre conflicts with every cell; removing it triangulates all 510
  // points again (a link past Impl::large_link, ordered before). Drained
  // after the centre's insertion, so its undo is a real removal.
  const std::vector<pdt::Point3> sphere = cospherical(2025);
  pdt::OpStream s;
  for (const pdt::Point3& p : sphere) s.ops.push_back({pdt::Operation::Kind::insert, p, 0});
  s.ops.push_back({pdt::Operation::Kind::insert, {0, 0, 0}, 0});
  s.ops.push_back({pdt::Operation::Kind::remove, {}, sphere.size()});
  s.box = bounding_box(sphere);
  pdt::Triangulation seq;
  replay_sequential(seq, s);
  for (unsigned threads : {1u, 3u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    const EngineRun run =
        replay_engine(t, s, *s.box, options_with(threads), ArenaMode::inside, 2, sphere.size() + 1);
    require_stats(run, s.ops.size(), threads);
    require_result(t, s, &seq);
  }
}

TEST_CASE("engine: insert_batch from a cancelled task group checks and inserts every point", "[engine][tsan]") {
  // A submission from a parallel loop whose sibling threw runs in a cancelled
  // TBB context: insert_batch's parallel steps (the checks, the order, the
  // sorted copy) must still run whole, not be skipped (which let bad points
  // through and left the sorted copy at (0, 0, 0)).
  std::vector<pdt::Point3> pts;
  for (int i = 0; i < 40000; ++i) pts.push_back({1 + (i % 37) * 0.01, 1 + (i % 101) * 0.005, 1 + (i % 13) * 0.03});
  const pdt::Box box{{1, 1, 1}, {2, 2, 2}};
  pdt::Triangulation t;
  bool refused = false, accepted = false;
  tbb::task_arena arena(2);
  arena.execute([&] {
    tbb::task_group group;
    group.run([&] {
      pdt::EngineOptions o;
      o.workers = 2;
      pdt::Engine e(t, box, o);
      group.cancel();
      std::vector<pdt::Point3> bad = pts;
      bad[12345] = {0.5, 1.5, 1.5};  // outside the domain
      try {
        e.insert_batch(bad);
      } catch (const pdt::Error& err) {
        refused = err.code() == pdt::ErrorCode::outside_domain;
      }
      e.insert_batch(pts);
      e.drain();
      accepted = true;
    });
    group.wait();
  });
  REQUIRE(refused);
  REQUIRE(accepted);
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("engine: a start with a big coplanar layer", "[engine][tsan]") {
  // 400 points in the plane z = 0 first (dimension 2 for all of them: global
  // operations), then random points in the cube, with removals interleaved.
  // The engine does not keep the stream's order across workers, so the layer
  // is drained before the rest is submitted (else a worker may raise the
  // dimension with an off-plane point first).
  const std::size_t layer = kTsan ? 150 : 400;
  std::vector<Point3> pts = random_points(layer, 31);
  for (auto& p : pts) p.z = 0;
  for (const Point3& p : random_points(scaled(2600, 300), 32)) pts.push_back(p);
  const pdt::OpStream s = stream_of(pts, 0.3, 33);
  // The head: the layer's insertions and the removals among them, all in dimension 2.
  std::size_t barrier = 0;
  while (barrier < s.ops.size() &&
         !(s.ops[barrier].kind == pdt::Operation::Kind::insert && s.ops[barrier].point.z != 0))
    ++barrier;
  REQUIRE(barrier >= layer);
  pdt::Triangulation seq;
  replay_sequential(seq, s);
  for (unsigned threads : {1u, 4u, 16u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(threads), ArenaMode::inside, 2, barrier);
    require_stats(run, s.ops.size(), threads);
    // Every operation on the flat layer ran with the world stopped, and so
    // did the one that built the first tetrahedra.
    REQUIRE(run.stats_at_barrier.global_operations == barrier);
    REQUIRE(run.stats.global_operations > barrier);
    require_result(t, s, &seq);
  }
}

TEST_CASE("engine: removals down to a coplanar set, to nothing, and back", "[engine][tsan]") {
  const std::size_t layer = kTsan ? 120 : 300, above = kTsan ? 120 : 300;
  std::vector<Point3> plane = random_points(layer, 41);
  for (auto& p : plane) p.z = 0.25;
  std::vector<Point3> cloud = random_points(above, 42);
  for (auto& p : cloud) p.z = 0.3 + 0.7 * p.z;  // strictly above the plane
  std::vector<Point3> all = plane;
  all.insert(all.end(), cloud.begin(), cloud.end());
  shuffle(all, 43);
  const pdt::Box box{{0, 0, 0}, {1, 1, 1}};

  for (unsigned threads : {2u, 16u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    tbb::task_arena arena(2);
    ErrorSink errors;
    arena.execute([&] {
      pdt::Engine e(t, box, options_with(threads));
      Watchdog watchdog(e, "coplanar removals");
      std::vector<pdt::Engine::Ticket> ticket(all.size());
      for (std::size_t i = 0; i < all.size(); ++i) ticket[i] = e.insert(all[i], errors.callback());
      e.drain();
      REQUIRE(t.dimension() == 3);
      require_valid(t);
      require_same_as_cgal(t, all);

      // Remove every point off the plane: the last removals leave a coplanar
      // set, which must run as a global operation (drop to dimension 2).
      const std::uint64_t globals_before = e.stats().global_operations;
      for (std::size_t i = 0; i < all.size(); ++i)
        if (all[i].z != 0.25) e.remove_insertion(ticket[i], errors.callback());
      e.drain();
      errors.require_none();
      REQUIRE(e.stats().global_operations > globals_before);
      REQUIRE(t.dimension() == 2);
      REQUIRE(t.number_of_vertices() == layer);
      REQUIRE(t.number_of_finite_cells() == 0);
      require_valid(t);
      require_same_as_cgal(t, plane);

      // Back to 3D: re-insert the cloud.
      std::vector<pdt::Engine::Ticket> again(cloud.size());
      for (std::size_t i = 0; i < cloud.size(); ++i) again[i] = e.insert(cloud[i], errors.callback());
      e.drain();
      REQUIRE(t.dimension() == 3);
      require_valid(t);
      std::vector<Point3> both = plane;
      both.insert(both.end(), cloud.begin(), cloud.end());
      require_same_as_cgal(t, both);

      // Everything out: down through dimensions 2, 1, 0 to empty.
      const std::uint64_t globals_mid = e.stats().global_operations;
      for (std::size_t i = 0; i < all.size(); ++i)
        if (all[i].z == 0.25) e.remove_insertion(ticket[i], errors.callback());
      for (auto tk : again) e.remove_insertion(tk, errors.callback());
      e.drain();
      errors.require_none();
      REQUIRE(e.stats().global_operations > globals_mid);
      REQUIRE(t.number_of_vertices() == 0);
      REQUIRE(t.dimension() == -1);
      REQUIRE(t.number_of_cells() == 0);
      require_valid(t);

      // And from nothing again, through the low dimensions to 3D.
      const std::uint64_t globals_empty = e.stats().global_operations;
      const std::vector<Point3> fresh = random_points(scaled(1500, 300), 44);
      for (const auto& p : fresh) e.insert(p, errors.callback());
      e.drain();
      errors.require_none();
      REQUIRE(e.stats().global_operations >= globals_empty + 4);
      require_valid(t);
      require_same_as_cgal(t, fresh);
      const pdt::EngineStats st = e.stats();
      const std::size_t ops = 2 * all.size() + 2 * cloud.size() + fresh.size();
      REQUIRE(st.total().completed == ops);
    });
  }
}

// =============================================================================
// 2. The paper's extreme case (§3.3): all insertions, then all removals
// =============================================================================
TEST_CASE("engine: 16 workers insert 3000 normal points then remove them all", "[engine][tsan]") {
  const std::size_t n = scaled(3000, 600);
  SECTION("remove all: empty at the end") {
    const pdt::OpStream s = generated(pdt::Distribution::normal, n, 1.0, pdt::RemovalOrder::after, 17);
    REQUIRE(s.remove_count() == n);
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(16));
    require_stats(run, s.ops.size(), 16);
    REQUIRE(run.stats.global_operations > 0);  // the last removals go below dimension 3
    REQUIRE(t.number_of_vertices() == 0);
    REQUIRE(t.dimension() == -1);
    REQUIRE(t.number_of_cells() == 0);
    require_valid(t);
  }
  SECTION("remove two thirds: CGAL's triangulation of the rest") {
    const pdt::OpStream s = generated(pdt::Distribution::normal, n, 2.0 / 3.0, pdt::RemovalOrder::after, 17);
    pdt::Triangulation seq;
    replay_sequential(seq, s);
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(16));
    require_stats(run, s.ops.size(), 16);
    require_result(t, s, &seq);
  }
  SECTION("remove all, each removal submitted right after its insertion") {
    // The removal may reach its worker before the insertion is done: it waits
    // (deferred), never fails.
    std::vector<Point3> pts;
    {
      const pdt::OpStream g = generated(pdt::Distribution::normal, n, 0, pdt::RemovalOrder::after, 18);
      for (const auto& op : g.ops) pts.push_back(op.point);
    }
    pdt::Triangulation t;
    tbb::task_arena arena(2);
    std::atomic<std::uint64_t> errors{0};
    pdt::EngineStats st;
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(16));
      Watchdog watchdog(e, "remove right after insert");
      auto count_errors = [&](const pdt::OpResult& r) {
        if (r.error) errors.fetch_add(1);
      };
      for (const auto& p : pts) e.remove_insertion(e.insert(p, count_errors), count_errors);
      e.drain();
      st = e.stats();
    });
    REQUIRE(errors.load() == 0);
    REQUIRE(st.total().completed == 2 * n);
    REQUIRE(t.number_of_vertices() == 0);
    require_valid(t);
  }
}

TEST_CASE("engine: a worker's idle time is counted, the stretch under way too", "[engine][tsan]") {
  // A worker waits for work from the engine's construction on, and after a
  // drain: the idle seconds grow while nothing is submitted (stats() counts
  // the stretch under way), by no more than the workers times the time that
  // passed, and never fall back.
  pdt::Triangulation t;
  const std::vector<Point3> pts = random_points(scaled(20000, 4000), 61);
  tbb::task_arena arena(4);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(4));
    {
      // Not started yet: waiting for work all the same, every one of the 4.
      const auto t0 = std::chrono::steady_clock::now();
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      const double idle = e.stats().total().seconds_idle;
      const double passed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      REQUIRE(idle >= 4 * 0.045);
      REQUIRE(idle <= 4 * passed + 0.05);  // made just before t0
    }
    ErrorSink errors;
    for (const auto& p : pts) e.insert(p, errors.callback());
    e.drain();
    errors.require_none();
    const double before = e.stats().total().seconds_idle;
    const auto t0 = std::chrono::steady_clock::now();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const double after = e.stats().total().seconds_idle;
    const double passed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    REQUIRE(before >= 0);
    REQUIRE(after >= before + 0.04);  // at least one worker idle all along
    REQUIRE(after <= before + 4 * passed + 0.01);
    // Work again: the stretches end, and what they held stays counted.
    for (const auto& p : random_points(2000, 62)) e.insert(p, errors.callback());
    e.drain();
    errors.require_none();
    REQUIRE(e.stats().total().seconds_idle >= after);
  });
  require_valid(t);
}

TEST_CASE("engine: the contention manager suspends a worker that keeps rolling back", "[engine][tsan]") {
  // Deterministic contention: the test itself holds one vertex's lock, so
  // removing that vertex rolls back until it lets go. With u- = u+ = 1 and a
  // window of 1 every rollback is a bad window: the worker must go to sleep as
  // soon as another worker is running, and the others must still finish.
  pdt::Triangulation t;
  const std::vector<Point3> base = random_points(scaled(2000, 400), 51);
  insert_all(t, base);
  const pdt::VertexId victim = t.nearest_vertex({0.5, 0.5, 0.5});
  REQUIRE(t.is_vertex(victim));
  const Point3 victim_point = t.point(victim);
  const std::vector<Point3> more = random_points(scaled(3000, 600), 52);

  pdt::EngineOptions o = options_with(8);
  o.contention_low = 1.0;
  o.contention_high = 1.0;
  o.contention_window = 1;
  o.escalate_after = 0;  // the contention manager alone (escalation is tested in test_engine_contract)
  pdt::detail::OpContext holder(999, true);
  ErrorSink errors;
  bool slept = false, removed_while_held = false;
  std::atomic<int> removal_done{0};
  std::atomic<std::uint64_t> reported_rollbacks{0};  // the OpResults' sum: each operation's own count
  pdt::EngineStats st;
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
    REQUIRE(pdt::detail::impl_of(t).lock_exclusive(holder, victim));
    e.remove(victim, [&](const pdt::OpResult& r) {
      reported_rollbacks += r.rollbacks;
      removal_done.store(r.error ? 2 : 1);
    });
    const pdt::Engine::Callback to_errors = errors.callback();
    for (const auto& p : more)
      e.insert(p, [&, to_errors](const pdt::OpResult& r) {
        reported_rollbacks += r.rollbacks;
        to_errors(r);
      });
    // Wait (at most 20 s) until the contention manager has put someone to sleep.
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (e.stats().total().sleeps == 0 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
    slept = e.stats().total().sleeps > 0;
    removed_while_held = removal_done.load() != 0;
    pdt::detail::impl_of(t).release_all(holder);
    e.drain();
    st = e.stats();
  });
  REQUIRE_FALSE(removed_while_held);
  REQUIRE(slept);
  REQUIRE(removal_done.load() == 1);
  const pdt::WorkerStats total = st.total();
  REQUIRE(total.rollbacks > 0);
  REQUIRE(total.max_rollbacks_per_completed > 0);
  REQUIRE(total.completed == more.size() + 1);
  REQUIRE(total.attempts == total.completed + total.rollbacks);
  CHECK(reported_rollbacks.load() == total.rollbacks);  // also without escalation (escalate_after = 0)
  REQUIRE(total.seconds_asleep >= 0);
  errors.require_none();
  // (The victim's id may have been recycled by a later insertion: look for its point.)
  const std::vector<Point3> left = surviving_points(t);
  REQUIRE(std::find(left.begin(), left.end(), victim_point) == left.end());
  require_valid(t);
  std::vector<Point3> expected;
  for (const auto& p : base)
    if (!(p == victim_point)) expected.push_back(p);
  expected.insert(expected.end(), more.begin(), more.end());
  require_same_as_cgal(t, expected);
}

// =============================================================================
// 3. The coroutine API
// =============================================================================
TEST_CASE("engine: co_await insert / remove from many concurrent coroutines", "[engine][tsan]") {
  const std::size_t per = scaled(400, 100);
  const int coroutines = 12;
  std::vector<std::vector<Point3>> sets;
  for (int c = 0; c < coroutines; ++c) sets.push_back(random_points(per, 100 + c));
  for (unsigned threads : {1u, 4u, 16u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    Tally tally;
    tbb::task_arena arena(2);
    bool all_finished = false;
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(threads));
      Watchdog watchdog(e, "coroutines");
      for (int c = 0; c < coroutines; ++c) churn(e, sets[c], tally);
      all_finished = wait_for(e, [&] { return tally.finished.load() == coroutines; });
    });
    REQUIRE(all_finished);
    INFO(failures_text(tally));
    REQUIRE(tally.failures.empty());
    require_valid(t);
    require_same_as_cgal(t, tally.kept);
    REQUIRE(total_multiplicity(t) == tally.kept.size());
  }
}

TEST_CASE("engine: coroutines started from threads outside the arena", "[engine][tsan]") {
  pdt::Triangulation t;
  Tally tally;
  tbb::task_arena arena(2);
  const std::size_t per = scaled(300, 80);
  {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(6), &arena);
    Watchdog watchdog(e, "coroutines from threads");
    std::vector<std::thread> threads;
    for (int c = 0; c < 4; ++c)
      threads.emplace_back([&, c] { churn(e, random_points(per, 300 + c), tally); });
    for (auto& th : threads) th.join();
    REQUIRE(wait_for(e, [&] { return tally.finished.load() == 4; }));
  }  // the destructor drains
  INFO(failures_text(tally));
  REQUIRE(tally.failures.empty());
  require_valid(t);
  require_same_as_cgal(t, tally.kept);
}

TEST_CASE("engine: co_await reports bad points and dead vertices as pdt::Error", "[engine]") {
  pdt::Triangulation t;
  const std::vector<Point3> base = random_points(200, 61);
  insert_all(t, base);
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(4));
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();

    for (Point3 bad : {Point3{nan, 0, 0}, Point3{0.5, inf, 0.5}, Point3{0.5, 0.5, -inf}}) {
      AwaitOutcome out;
      await_insert(e, bad, out);  // fails at once: the coroutine never suspends
      REQUIRE(out.done.load());
      REQUIRE(out.code == pdt::ErrorCode::non_finite_coordinate);
    }
    for (Point3 outside : {Point3{1.5, 0.5, 0.5}, Point3{0.5, -1e-300, 0.5}, Point3{0.5, 0.5, 1.0000001}}) {
      AwaitOutcome out;
      await_insert(e, outside, out);
      REQUIRE(out.done.load());
      REQUIRE(out.code == pdt::ErrorCode::outside_domain);
      REQUIRE(out.message.find("domain") != std::string::npos);
    }
    // A point on the box boundary is inside the domain.
    {
      AwaitOutcome out;
      await_insert(e, {1.0, 0.0, 0.5}, out);
      REQUIRE(wait_for(e, [&] { return out.done.load(); }));
      REQUIRE_FALSE(out.code.has_value());
    }
    // remove: the infinite vertex, ids never issued, a vertex removed before.
    for (pdt::VertexId v : {pdt::infinite_vertex, pdt::VertexId{123456789}, pdt::no_vertex}) {
      AwaitOutcome out;
      await_remove(e, v, out);
      REQUIRE(out.done.load());
      REQUIRE(out.code == pdt::ErrorCode::unknown_vertex);
    }
    std::atomic<pdt::VertexId> v{pdt::no_vertex};
    std::atomic<int> state{0};
    insert_then_remove(e, {0.123, 0.456, 0.789}, v, state);
    REQUIRE(wait_for(e, [&] { return state.load() == 1; }));
    REQUIRE(v.load() != pdt::no_vertex);
    AwaitOutcome dead;
    await_remove(e, v.load(), dead);
    REQUIRE(wait_for(e, [&] { return dead.done.load(); }));
    REQUIRE(dead.code == pdt::ErrorCode::unknown_vertex);
    e.drain();
  });
  // Nothing the failed operations named was changed.
  std::vector<Point3> expected = base;
  expected.push_back({1.0, 0.0, 0.5});
  require_valid(t);
  require_same_as_cgal(t, expected);
}

// =============================================================================
// 4. Callback form
// =============================================================================
TEST_CASE("engine: callbacks report each insertion's result by ticket", "[engine][tsan]") {
  const std::vector<Point3> pts = random_points(scaled(3000, 500), 71);
  pdt::Triangulation t;
  std::vector<pdt::OpResult> results(pts.size());
  std::vector<std::atomic<int>> calls(pts.size());
  std::atomic<std::size_t> callbacks{0};
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(8));
    Watchdog watchdog(e, "callbacks");
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const pdt::Engine::Ticket tk = e.insert(pts[i], [&, i](const pdt::OpResult& r) {
        results[i] = r;  // slot i is written by this callback only
        calls[i].fetch_add(1);
        callbacks.fetch_add(1);
      });
      REQUIRE(tk == i);
    }
    e.drain();
  });
  REQUIRE(callbacks.load() == pts.size());
  std::vector<pdt::VertexId> seen;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    REQUIRE(calls[i].load() == 1);
    REQUIRE_FALSE(results[i].error);
    REQUIRE(results[i].insert.inserted);
    REQUIRE(t.is_vertex(results[i].insert.vertex));
    REQUIRE(t.point(results[i].insert.vertex) == pts[i]);
    seen.push_back(results[i].insert.vertex);
  }
  std::sort(seen.begin(), seen.end());
  REQUIRE(std::adjacent_find(seen.begin(), seen.end()) == seen.end());
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("engine: several threads submit at once", "[engine][tsan]") {
  const int submitters = 4;
  const std::size_t per = scaled(1500, 250);
  std::vector<std::vector<Point3>> sets;
  for (int s = 0; s < submitters; ++s) sets.push_back(random_points(per, 80 + s));
  pdt::Triangulation t;
  tbb::task_arena arena(2);
  std::mutex m;
  std::vector<pdt::Engine::Ticket> tickets;
  std::atomic<int> errors{0};
  {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(16), &arena);
    Watchdog watchdog(e, "several submitters");
    std::vector<std::thread> threads;
    for (int s = 0; s < submitters; ++s)
      threads.emplace_back([&, s] {
        std::vector<pdt::Engine::Ticket> mine;
        for (std::size_t i = 0; i < per; ++i) {
          mine.push_back(e.insert(sets[s][i], [&](const pdt::OpResult& r) {
            if (r.error) errors.fetch_add(1);
          }));
          // Undo every other insertion of this thread, right away.
          if (i % 2 == 1) e.remove_insertion(mine[i - 1], [&](const pdt::OpResult& r) {
              if (r.error) errors.fetch_add(1);
            });
        }
        std::lock_guard lock(m);
        tickets.insert(tickets.end(), mine.begin(), mine.end());
      });
    for (auto& th : threads) th.join();
    e.drain();
    const pdt::EngineStats st = e.stats();
    REQUIRE(st.total().completed == submitters * (per + per / 2));
  }
  REQUIRE(errors.load() == 0);
  // Tickets are unique and number the insertions from 0.
  std::sort(tickets.begin(), tickets.end());
  REQUIRE(tickets.size() == submitters * per);
  for (std::size_t i = 0; i < tickets.size(); ++i) REQUIRE(tickets[i] == i);
  std::vector<Point3> expected;
  for (int s = 0; s < submitters; ++s)
    for (std::size_t i = 0; i < per; ++i)
      if (i % 2 == 1 || i + 1 == per) expected.push_back(sets[s][i]);
  require_valid(t);
  require_same_as_cgal(t, expected);
}

TEST_CASE("engine: submitting never waits for a worker, so a submitter may hold a lock its hook takes",
          "[engine][tsan]") {
  // The arena (one thread, two slots) is full: its thread runs the first
  // insertion, whose change hook waits for m, which the submitter holds, and
  // another outside thread sits in the second slot. The submitter then
  // submits to idle workers, which must be started. When a submission
  // entered the arena for that (task_arena::execute), it waited for a free
  // slot or thread: a deadlock (found with producers booking tickets under a
  // lock the hook also takes). Now it enqueues and returns at once.
  pdt::Triangulation t;
  std::mutex m;
  std::atomic<int> in_hook{0};
  std::atomic<bool> occupant_in{false}, submitted{false}, finished{false};
  std::thread stall_check([&] {
    for (int waited = 0; !finished.load(); ++waited) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      if (waited > (kTsan ? 1200 : 300)) {
        std::fprintf(stderr, "\n[submit-lock test] stuck for 30 s (submissions returned: %d): a submission waits "
                             "for the arena\n", submitted.load() ? 1 : 0);
        std::_Exit(1);
      }
    }
  });
  {
    tbb::task_arena arena(1, 0);
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(8), &arena);
    e.set_change_hook([&](const pdt::Changes&) {
      in_hook.fetch_add(1);
      std::lock_guard lock(m);
    });
    std::thread occupant;
    {
      std::unique_lock lock(m);
      (void)e.insert(Point3{0.01, 0.02, 0.03}, {});
      while (in_hook.load() == 0) std::this_thread::yield();  // the arena's thread waits for m
      occupant = std::thread([&] {
        arena.execute([&] {
          occupant_in.store(true);
          while (!submitted.load()) std::this_thread::yield();
        });
      });
      while (!occupant_in.load()) std::this_thread::yield();
      // Points all over: the other workers' homes, idle, so they are started.
      for (const Point3& p : random_points(64, 5)) (void)e.insert(p, {});
      submitted.store(true);
    }
    occupant.join();
    e.drain();
    CHECK(in_hook.load() == 65);
  }
  finished.store(true);
  stall_check.join();
  CHECK(t.number_of_vertices() == 65);
}

TEST_CASE("engine: duplicates, remove_insertion and immediate errors of the callback form", "[engine]") {
  pdt::Triangulation t;
  const std::vector<Point3> base = random_points(500, 91);
  insert_all(t, base);
  const std::size_t nv = t.number_of_vertices();
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(4));
    const Point3 p{0.31, 0.62, 0.93};
    pdt::OpResult r1, r2;
    const auto t1 = e.insert(p, [&](const pdt::OpResult& r) { r1 = r; });
    const auto t2 = e.insert(p, [&](const pdt::OpResult& r) { r2 = r; });
    REQUIRE(t1 == 0);
    REQUIRE(t2 == 1);
    e.drain();
    REQUIRE_FALSE(r1.error);
    REQUIRE_FALSE(r2.error);
    REQUIRE(r1.insert.vertex == r2.insert.vertex);
    REQUIRE(r1.insert.inserted != r2.insert.inserted);  // exactly one of them created the vertex
    const pdt::VertexId v = r1.insert.vertex;
    REQUIRE(t.multiplicity(v) == 2);
    REQUIRE(t.number_of_vertices() == nv + 1);

    pdt::OpResult u1;
    e.remove_insertion(t1, [&](const pdt::OpResult& r) { u1 = r; });
    e.drain();
    REQUIRE_FALSE(u1.error);
    REQUIRE(u1.remove == pdt::RemoveResult::multiplicity_lowered);
    REQUIRE(t.is_vertex(v));
    REQUIRE(t.multiplicity(v) == 1);
    // Undoing a ticket twice, or one never issued, fails at once.
    REQUIRE(error_of([&] { e.remove_insertion(t1); }) == pdt::ErrorCode::unknown_vertex);
    REQUIRE(error_of([&] { e.remove_insertion(12345); }) == pdt::ErrorCode::unknown_vertex);
    REQUIRE(error_of([&] { e.remove_insertion(t2 + 1); }) == pdt::ErrorCode::unknown_vertex);

    pdt::OpResult u2;
    e.remove_insertion(t2, [&](const pdt::OpResult& r) { u2 = r; });
    e.drain();
    REQUIRE_FALSE(u2.error);
    REQUIRE(u2.remove == pdt::RemoveResult::removed);
    REQUIRE_FALSE(t.is_vertex(v));
    REQUIRE(t.number_of_vertices() == nv);
    REQUIRE(error_of([&] { e.remove_insertion(t2); }) == pdt::ErrorCode::unknown_vertex);

    // Bad points are refused at once and submit nothing (no ticket used).
    const double nan = std::numeric_limits<double>::quiet_NaN();
    bool called = false;
    std::string msg;
    REQUIRE(error_of([&] { e.insert({nan, 0.5, 0.5}, [&](const pdt::OpResult&) { called = true; }); }, &msg) ==
            pdt::ErrorCode::non_finite_coordinate);
    REQUIRE(error_of([&] { e.insert({0.5, 0.5, std::numeric_limits<double>::infinity()}, {}); }) ==
            pdt::ErrorCode::non_finite_coordinate);
    REQUIRE(error_of([&] { e.insert({0.5, 2.0, 0.5}, [&](const pdt::OpResult&) { called = true; }); }, &msg) ==
            pdt::ErrorCode::outside_domain);
    REQUIRE(error_of([&] { e.insert({-0.0001, 0.5, 0.5}, {}); }) == pdt::ErrorCode::outside_domain);
    // Engine::remove of dead or impossible vertices fails at once too.
    REQUIRE(error_of([&] { e.remove(v, {}); }) == pdt::ErrorCode::unknown_vertex);
    REQUIRE(error_of([&] { e.remove(pdt::infinite_vertex, {}); }) == pdt::ErrorCode::unknown_vertex);
    REQUIRE(error_of([&] { e.remove(pdt::no_vertex, {}); }) == pdt::ErrorCode::unknown_vertex);
    e.drain();
    REQUIRE_FALSE(called);
    REQUIRE(t.number_of_vertices() == nv);
    const auto next = e.insert({0.2, 0.2, 0.2}, {});
    REQUIRE(next == t2 + 1);  // the refused insertions took no ticket
    e.drain();
    const pdt::EngineStats st = e.stats();
    REQUIRE(st.total().completed == 5);  // 2 inserts, 2 undos, 1 insert
  });
  std::vector<Point3> expected = base;
  expected.push_back({0.2, 0.2, 0.2});
  require_valid(t);
  require_same_as_cgal(t, expected);
}

TEST_CASE("engine: insert_batch gives CGAL's triangulation; tickets follow the batch's order", "[engine][tsan]") {
  const std::vector<Point3> pts = random_points(scaled(20000, 2000), 95);
  std::vector<Point3> batch(pts.begin(), pts.begin() + static_cast<std::ptrdiff_t>(pts.size() / 2));
  batch.insert(batch.end(), batch.begin(), batch.begin() + 100);  // duplicates within the batch
  const std::vector<Point3> singles(pts.begin() + static_cast<std::ptrdiff_t>(pts.size() / 2), pts.end());
  for (unsigned threads : {1u, 4u, 16u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    std::vector<pdt::InsertResult> results(batch.size());
    std::vector<int> calls(batch.size(), 0);
    std::optional<pdt::ErrorCode> refused;
    bool ticket_error = false;
    pdt::Engine::Ticket first = 0;
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(threads));
      ErrorSink errors;
      for (std::size_t i = 0; i < singles.size() / 2; ++i) e.insert(singles[i], errors.callback());
      // Callbacks run before insert_batch returns: they use the ticket the
      // batch must start at, not `first` (checked below).
      const pdt::Engine::Ticket expected_first = singles.size() / 2;
      first = e.insert_batch(batch, [&, expected_first](const pdt::OpResult& r) {
        if (r.error || r.ticket < expected_first || r.ticket >= expected_first + batch.size()) {
          ticket_error = true;
          return;
        }
        ++calls[r.ticket - expected_first];  // each ticket is called exactly once, on one thread
      });
      for (std::size_t i = singles.size() / 2; i < singles.size(); ++i) e.insert(singles[i], errors.callback());
      // A batch with one point outside the domain is refused whole.
      std::vector<Point3> bad = {{0.5, 0.5, 0.5}, {0.5, 1.5, 0.5}};
      refused = error_of([&] { e.insert_batch(bad); });
      e.drain();
      errors.require_none();
      for (std::size_t i = 0; i < batch.size(); ++i) results[i] = e.insertion_result(first + i);
      REQUIRE(error_of([&] { e.insertion_result(first + batch.size() + singles.size()); }) ==
              pdt::ErrorCode::invalid_argument);
    });
    REQUIRE(first == singles.size() / 2);
    REQUIRE_FALSE(ticket_error);
    REQUIRE(std::all_of(calls.begin(), calls.end(), [](int c) { return c == 1; }));
    REQUIRE(refused == pdt::ErrorCode::outside_domain);
    std::size_t fresh = 0;
    for (std::size_t i = 0; i < batch.size(); ++i) {
      REQUIRE(t.is_vertex(results[i].vertex));
      REQUIRE(t.point(results[i].vertex) == batch[i]);
      fresh += results[i].inserted;
    }
    REQUIRE(fresh == batch.size() - 100);
    require_valid(t);
    require_same_as_cgal(t, pts);
  }
}

TEST_CASE("engine: one worker inserts a batch in its spatial order, a run not cut into slices", "[engine][tsan]") {
  // A worker serves up to 64 operations per claim of a block; a run of an
  // insert_batch (up to 256 points) it has not finished goes back to the
  // front of the block, so the next claim goes on with it. Fresh vertex ids
  // are handed out in increasing order (one worker, one pool), so along the
  // batch's spatial order they must increase: a remainder sent to the back
  // would interleave the block's runs in slices of 64 (ids falling at each
  // run's end).
  const std::vector<Point3> pts = random_points(scaled(5000, 2000), 96);
  pdt::EngineOptions o = options_with(1);
  o.blocks_per_axis = 1;  // every run in one block
  pdt::Triangulation t;
  std::vector<pdt::InsertResult> results(pts.size());
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
    const pdt::Engine::Ticket first = e.insert_batch(pts);
    e.drain();
    for (std::size_t i = 0; i < pts.size(); ++i) results[i] = e.insertion_result(first + i);
  });
  const std::vector<std::uint32_t> order = pdt::detail::spatial_order(pts, true);  // the engine's
  std::size_t falls = 0;
  for (std::size_t k = 1; k < order.size(); ++k) {
    REQUIRE(results[order[k]].inserted);
    falls += results[order[k]].vertex < results[order[k - 1]].vertex;
  }
  CHECK(falls == 0);
  require_valid(t);
  require_same_as_cgal(t, pts);
}

TEST_CASE("engine: one worker takes a batch's rounds block after block, as the sequential batch does",
          "[engine][tsan]") {
  // The batch's order is rounds of a biased randomized order, so each block's
  // queue holds a stretch of every round. A worker that served up to 1,024
  // operations of a block in a row, through several rounds, inserted a dense
  // block beside empty ones: measured, 16% more cells made than the sequential batch at 20k uniform
  // points (5% at 1M). Moving on when the next run is a later round keeps
  // the rounds' order, and the work with it, within a few percent. Moving on
  // at every break in the order instead (a round's stretch in a block can
  // come in pieces) walked 32 steps per insertion on 20k line points (73 at
  // 500k; the sequential batch: 6), each walk starting in the block left.
  // A claim's first run was still taken whatever its round: a worker that
  // came to a block without a run of its round took the next round's there
  // while its other blocks still held runs of the round before (1.3-3% more
  // cells made at 4k-20k points, line walks 1.11-1.15x). Since then a claim
  // puts such a run back and moves on, until it has seen its home around.
  // 4,000 points in every build (the TSan build's only size), and 20,000
  // outside TSan: a batch's insertions left out of the jump grid walked
  // 1.89x at 4,000 line points and only 1.13x at 20,000 (a run's first walk
  // starts from the grid).
  std::vector<std::size_t> sizes{4000};
  if (scaled(20000, 4000) > 4000) sizes.push_back(20000);
  for (const std::size_t n : sizes) {
    for (const pdt::Distribution dist :
         {pdt::Distribution::uniform, pdt::Distribution::normal, pdt::Distribution::line}) {
      const std::vector<Point3> pts = generated_points(dist, n, 97);
      pdt::Triangulation seq;
      (void)seq.insert_batch(pts);
      pdt::Triangulation t;
      tbb::task_arena arena(2);
      arena.execute([&] {
        pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(1));
        REQUIRE(e.blocks_per_axis() >= 8);  // many blocks: each holds a stretch of every round
        (void)e.insert_batch(pts);
        e.drain();
      });
      const pdt::TriangulationStats& st = t.stats();
      const pdt::TriangulationStats& st_seq = seq.stats();
      INFO(n << " " << pdt::to_string(dist) << ": cells made by the engine's batch / by the sequential batch: "
           << double(st.cells_created_by_insert) / double(st_seq.cells_created_by_insert)
           << ", walk steps: " << double(st.walk_steps) / double(st_seq.walk_steps));
      CHECK(double(st.cells_created_by_insert) <= 1.015 * double(st_seq.cells_created_by_insert));
      CHECK(double(st.walk_steps) <= 1.2 * double(st_seq.walk_steps));
      require_same_as_cgal(t, pts);
    }
  }
}

TEST_CASE("engine: a ticket is released once its vertex is removed by id or handle", "[engine]") {
  pdt::Triangulation t;
  insert_all(t, random_points(200, 17));
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(2));
    const Point3 p{0.2, 0.3, 0.4}, q{0.6, 0.7, 0.8};
    const auto tp = e.insert(p, {});
    const auto tq = e.insert(q, {});
    const auto tb = e.insert_batch(std::vector<Point3>{{0.15, 0.25, 0.35}, {0.45, 0.55, 0.65}});
    e.drain();
    const pdt::InsertResult rp = e.insertion_result(tp), rq = e.insertion_result(tq);
    const pdt::InsertResult rb = e.insertion_result(tb + 1);
    e.remove(rp.vertex, {});    // by id
    e.remove(rq.handle(), {});  // by handle
    e.remove(rb.handle(), {});
    e.drain();
    // The same point again: a new incarnation, perhaps with the old id.
    const auto tp2 = e.insert(p, {});
    e.drain();
    REQUIRE(e.insertion_result(tp2).inserted);
    for (auto gone : {tp, tq, tb + 1}) {
      std::string msg;
      REQUIRE(error_of([&] { (void)e.insertion_result(gone); }, &msg) == pdt::ErrorCode::invalid_argument);
      REQUIRE(msg.find("released") != std::string::npos);
      REQUIRE(error_of([&] { e.remove_insertion(gone); }, &msg) == pdt::ErrorCode::unknown_vertex);
      REQUIRE(msg.find("removed") != std::string::npos);
      REQUIRE(error_of([&] { e.remove_insertion(gone); }) == pdt::ErrorCode::unknown_vertex);  // and stays so
    }
    // A batch of undos naming one released ticket undoes nothing.
    const std::vector<pdt::Engine::Ticket> mixed{tb, tb + 1};
    REQUIRE(error_of([&] { e.remove_insertions(mixed); }) == pdt::ErrorCode::unknown_vertex);
    e.drain();
    REQUIRE(e.insertion_result(tb).inserted);  // still there, still undoable
    // The new incarnation was never touched by the refused undos.
    REQUIRE(t.is_vertex(e.insertion_result(tp2).handle()));
    e.remove_insertion(tb, {});
    e.remove_insertion(tp2, {});
    e.drain();
  });
  REQUIRE(t.number_of_vertices() == 200);
  require_valid(t);
}

TEST_CASE("engine: remove_insertions undoes a batch, all or nothing", "[engine][tsan]") {
  const std::vector<Point3> pts = random_points(scaled(10000, 1500), 98);
  for (unsigned threads : {1u, 8u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    std::optional<pdt::ErrorCode> repeated, unknown;
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(threads));
      ErrorSink errors;
      const pdt::Engine::Ticket first = e.insert_batch(pts, errors.callback());
      // Undo the even insertions, submitted before the batch has finished.
      std::vector<pdt::Engine::Ticket> evens;
      for (std::size_t i = 0; i < pts.size(); i += 2) evens.push_back(first + i);
      std::vector<pdt::Engine::Ticket> with_repeat = {first + 1, first + 3, first + 1};
      std::string why;
      repeated = error_of([&] { e.remove_insertions(with_repeat); }, &why);
      CHECK(why.find("ticket " + std::to_string(first + 1) + " appears twice in the batch") != std::string::npos);
      std::vector<pdt::Engine::Ticket> with_unknown = {first + 1, first + pts.size() + 7};
      unknown = error_of([&] { e.remove_insertions(with_unknown); });
      e.remove_insertions(evens, errors.callback());
      e.drain();
      errors.require_none();
      // The refused batches claimed nothing: their odd tickets can still be undone one by one.
      e.remove_insertion(first + 1, errors.callback());
      e.remove_insertion(first + 3, errors.callback());
      e.drain();
      errors.require_none();
    });
    REQUIRE(repeated == pdt::ErrorCode::unknown_vertex);
    REQUIRE(unknown == pdt::ErrorCode::unknown_vertex);
    std::vector<Point3> expected;
    for (std::size_t i = 5; i < pts.size(); i += 2) expected.push_back(pts[i]);
    require_valid(t);
    require_same_as_cgal(t, expected);
  }
}

TEST_CASE("engine: a large batch mostly undone keeps the rest by ticket", "[engine][tsan]") {
  // A batch this size keeps its tickets in a range (tickets.hpp); undoing 15
  // of every 16, some before they ran (parked), compacts the range into the
  // hashed shards: the rest must still be found, read and undone by ticket.
  const std::vector<Point3> pts = random_points(scaled(8000, 2000), 99);
  pdt::Triangulation t;
  std::vector<Point3> kept_points;
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(2));
    ErrorSink errors;
    const pdt::Engine::Ticket first = e.insert_batch(pts, errors.callback());
    std::vector<pdt::Engine::Ticket> undo, kept;
    for (std::size_t i = 0; i < pts.size(); ++i) (i % 16 == 5 ? kept : undo).push_back(first + i);
    e.remove_insertions(undo, errors.callback());
    e.drain();
    errors.require_none();
    for (const pdt::Engine::Ticket k : kept) {
      const pdt::InsertResult r = e.insertion_result(k);
      REQUIRE(r.inserted);
      REQUIRE(t.is_vertex(r.handle()));
      kept_points.push_back(pts[k - first]);
    }
    for (const pdt::Engine::Ticket u : {undo.front(), undo.back()})
      REQUIRE(error_of([&] { (void)e.insertion_result(u); }) == pdt::ErrorCode::invalid_argument);
    REQUIRE(t.number_of_vertices() == kept.size());
    require_valid(t);
    require_same_as_cgal(t, kept_points);
    for (const pdt::Engine::Ticket k : kept) e.remove_insertion(k, errors.callback());
    e.drain();
    errors.require_none();
  });
  REQUIRE(t.number_of_vertices() == 0);
}

namespace {
// Submits pts one at a time to an engine of `workers` over `domain`, in an
// arena of `threads`; checks the result against CGAL; returns the walk steps
// per insertion.
double engine_walk_steps(const std::vector<Point3>& pts, unsigned workers, int threads,
                         const pdt::Box& domain = {{0, 0, 0}, {1, 1, 1}}) {
  pdt::Triangulation t;
  tbb::task_arena arena(threads);
  arena.execute([&] {
    pdt::Engine e(t, domain, options_with(workers));
    ErrorSink errors;
    for (const auto& p : pts) e.insert(p, errors.callback());
    e.drain();
    errors.require_none();
  });
  require_valid(t);
  require_same_as_cgal(t, pts);
  return double(t.stats().walk_steps) / double(t.stats().insertions);
}
}  // namespace

TEST_CASE("engine: a domain reaching the largest doubles", "[engine][extreme]") {
  // The domain check and the block routing must not overflow either.
  const double m = std::numeric_limits<double>::max();
  std::vector<Point3> pts;
  for (int x : {-1, 1})
    for (int y : {-1, 1})
      for (int z : {-1, 1}) pts.push_back({x * m, y * m, z * m});
  for (const auto& p : random_points(2000, 96, -1, 1)) pts.push_back({p.x * m, p.y * m, p.z * m});
  for (const auto& p : random_points(500, 97, -1, 1)) pts.push_back({p.x * 1e-300, p.y, p.z * 1e300});
  (void)engine_walk_steps(pts, 4, 2, {{-m, -m, -m}, {m, m, m}});
}

TEST_CASE("engine: drain() from the engine's own callback is refused, not a deadlock", "[engine]") {
  pdt::Triangulation t;
  insert_all(t, random_points(300, 93));
  std::optional<pdt::ErrorCode> from_callback;
  std::string message;
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(2));
    // The callback runs inside the engine's task; only record there (Catch2's
    // assertions are not thread-safe), check after drain.
    e.insert({0.4, 0.4, 0.4}, [&](const pdt::OpResult&) { from_callback = error_of([&] { e.drain(); }, &message); });
    e.drain();
  });
  REQUIRE(from_callback == pdt::ErrorCode::invalid_argument);
  REQUIRE(message.find("drain()") != std::string::npos);
  require_valid(t);
}

TEST_CASE("engine: the jump grid grows with the vertex count, up to grid_slots", "[engine]") {
  // Inserts points one at a time with a grid of at most `cap` slots,
  // draining after every `drain_every` of them (0: once, at the end).
  auto run = [](pdt::Triangulation& t, const std::vector<Point3>& points, std::size_t cap,
                std::size_t drain_every = 0) {
    pdt::EngineOptions o = options_with(2);
    o.grid_slots = cap;
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
      ErrorSink errors;
      for (std::size_t i = 0; i < points.size(); ++i) {
        e.insert(points[i], errors.callback());
        if (drain_every != 0 && (i + 1) % drain_every == 0) e.drain();
      }
      e.drain();
      errors.require_none();
    });
  };
  // Clustered points take the cut grid (build_split), within the cap too.
  // Drained every 256 points, so that each regrowth sees a prefix of the
  // stream, half of it in the clusters: without the drains, which vertices
  // are live at a regrowth depends on the order the workers served the
  // blocks (under TSan the clusters' blocks could still be queued, the grid
  // then built of equal slots, and whether the walk watch cuts it later
  // depends on the walks each worker saw). With the drains, a regrowth at n
  // live vertices sees at least n - 256 of the prefix: crowded at least
  // (n - 256) / 2n, over the 40% that cuts from n = 1,280 on.
  pdt::GenerateOptions clustered;
  clustered.points = scaled(20000, 8000);
  clustered.dist = pdt::Distribution::clusters;
  std::vector<Point3> cpts{{0, 0, 0}, {1, 1, 1}};
  for (const pdt::Operation& op : pdt::generate(clustered).ops) cpts.push_back(op.point);
  for (std::size_t cap : {std::size_t{1} << 23, std::size_t{1000}, std::size_t{1}}) {
    pdt::Triangulation t;
    run(t, cpts, cap, 256);
    const auto& grid = pdt::detail::impl_of(t).grid;
    INFO("clustered points, cap " << cap << ", slots " << grid.slot_count << ", nodes " << grid.node_count);
    REQUIRE(grid.slot_count <= cap);
    REQUIRE(grid.check());
    if (cap > cpts.size()) {
      REQUIRE(grid.node_count > 1);  // cut where the clusters are
      CHECK(double(t.stats().walk_steps) / double(t.stats().insertions) < 20);
    }
    require_valid(t);
  }
  const std::vector<Point3> pts = random_points(scaled(20000, 8000), 94);
  for (std::size_t cap : {std::size_t{1} << 23, std::size_t{1000}}) {
    pdt::Triangulation t;
    run(t, pts, cap);
    const std::size_t slots = pdt::detail::impl_of(t).grid.slot_count;
    INFO("cap " << cap << ", slots " << slots << ", points " << pts.size());
    // Regrown as ids double, at about two vertices per slot: between n/8 and n/2.
    if (cap >= pts.size()) {
      REQUIRE(slots >= pts.size() / 8);
      REQUIRE(slots <= pts.size() / 2);
    } else {
      REQUIRE(slots <= cap);
      REQUIRE(slots >= cap / 2);
    }
    require_valid(t);
    require_same_as_cgal(t, pts);
  }
}

// =============================================================================
// 5. Options
// =============================================================================
TEST_CASE("engine: EngineOptions::from_environment reads the PDT_* variables", "[engine]") {
  for (const char* n : {"PDT_WORKERS", "PDT_THREADS", "PDT_BLOCKS_PER_AXIS", "PDT_CONTENTION_LOW", "PDT_CONTENTION_HIGH",
                        "PDT_CONTENTION_WINDOW", "PDT_GRID_SLOTS"})
    ::unsetenv(n);
  SECTION("unset: the defaults given") {
    pdt::EngineOptions d;
    d.workers = 7;
    d.contention_window = 5;
    const pdt::EngineOptions o = pdt::EngineOptions::from_environment(d);
    REQUIRE(o.workers == 7);
    REQUIRE(o.contention_window == 5);
    REQUIRE(o.blocks_per_axis == 0);
    REQUIRE(o.contention_low == 0.7);
    REQUIRE(o.contention_high == 0.9);
    REQUIRE(o.grid_slots == (std::size_t{1} << 23));
    const pdt::EngineOptions plain = pdt::EngineOptions::from_environment();
    REQUIRE(plain.workers == 0);
  }
  SECTION("set to the empty string: as unset") {
    EnvGuard env;
    env.set("PDT_WORKERS", "");
    env.set("PDT_CONTENTION_LOW", "");
    pdt::EngineOptions d;
    d.workers = 7;
    const pdt::EngineOptions o = pdt::EngineOptions::from_environment(d);
    REQUIRE(o.workers == 7);
    REQUIRE(o.contention_low == 0.7);
  }
  SECTION("PDT_THREADS, the 0.1 name of PDT_WORKERS, still counts; PDT_WORKERS wins") {
    EnvGuard env;
    env.set("PDT_THREADS", "3");
    REQUIRE(pdt::EngineOptions::from_environment().workers == 3);
    env.set("PDT_WORKERS", "5");
    REQUIRE(pdt::EngineOptions::from_environment().workers == 5);
  }
  SECTION("every variable") {
    EnvGuard env;
    env.set("PDT_WORKERS", "6");
    env.set("PDT_BLOCKS_PER_AXIS", "5");
    env.set("PDT_CONTENTION_LOW", ".25");  // decimal forms: a leading point, an exponent
    env.set("PDT_CONTENTION_HIGH", "5e-1");
    env.set("PDT_CONTENTION_WINDOW", "64");
    env.set("PDT_GRID_SLOTS", "4096");
    const pdt::EngineOptions o = pdt::EngineOptions::from_environment();
    REQUIRE(o.workers == 6);
    REQUIRE(o.blocks_per_axis == 5);
    REQUIRE(o.contention_low == 0.25);
    REQUIRE(o.contention_high == 0.5);
    REQUIRE(o.contention_window == 64);
    REQUIRE(o.grid_slots == 4096);
    // An engine built from them reports them.
    pdt::Triangulation t;
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}});  // default argument: from_environment()
      REQUIRE(e.workers() == 6);
      REQUIRE(e.blocks_per_axis() == 5);
      REQUIRE(e.options().contention_low == 0.25);
      REQUIRE(e.options().contention_window == 64);
      for (const auto& p : random_points(300, 3)) e.insert(p, {});
      e.drain();
      REQUIRE(e.stats().workers.size() == 6);
    });
    require_same_as_cgal(t, random_points(300, 3));
  }
  SECTION("a bad value is refused, naming the variable") {
    const std::pair<const char*, const char*> bad[] = {
        {"PDT_THREADS", "abc"},          {"PDT_THREADS", "-1"},        {"PDT_THREADS", "2.5"},
        {"PDT_BLOCKS_PER_AXIS", "4x"},   {"PDT_CONTENTION_LOW", "nan"}, {"PDT_CONTENTION_HIGH", "-0.5"},
        {"PDT_CONTENTION_WINDOW", "1e99"}, {"PDT_GRID_SLOTS", " "},     {"PDT_CONTENTION_LOW", "inf"},
        // Past the field's range (32 bits): refused, not wrapped to 1 or 0.
        {"PDT_WORKERS", "4294967297"},   {"PDT_CONTENTION_WINDOW", "4294967296"},
        {"PDT_ESCALATE_AFTER", "4294967360"}, {"PDT_BLOCKS_PER_AXIS", "4294967300"},
        // Past the option's own range, and numbers that are not plain decimals.
        {"PDT_WORKERS", "4097"}, {"PDT_BLOCKS_PER_AXIS", "65"}, {"PDT_CONTENTION_LOW", "1.5"},
        {"PDT_STEALING", "2"}, {"PDT_WORKERS", "0x4"}, {"PDT_WORKERS", "1e1"}, {"PDT_WORKERS", "+3"},
        {"PDT_WORKERS", " 3"}, {"PDT_WORKERS", "3 "}, {"PDT_ESCALATE_AFTER", "0x10"}, {"PDT_CONTENTION_HIGH", ".5e"}};
    for (const auto& [name, value] : bad) {
      EnvGuard env;
      env.set(name, value);
      std::string msg;
      INFO(name << "='" << value << "'");
      REQUIRE(error_of([] { (void)pdt::EngineOptions::from_environment(); }, &msg) == pdt::ErrorCode::invalid_argument);
      INFO(msg);
      REQUIRE(msg.find(name) != std::string::npos);
    }
    // The message gives the option's real range.
    EnvGuard env;
    env.set("PDT_WORKERS", "5000");
    std::string msg;
    (void)error_of([] { (void)pdt::EngineOptions::from_environment(); }, &msg);
    CHECK(msg.find("expected a whole number from 0 to 4096") != std::string::npos);
  }
  SECTION("thresholds that cross are refused, naming both variables") {
    for (const auto& [low, high] : {std::pair<const char*, const char*>{"0.95", nullptr}, {nullptr, "0.5"}, {"0.8", "0.6"}}) {
      EnvGuard env;
      if (low) env.set("PDT_CONTENTION_LOW", low);
      if (high) env.set("PDT_CONTENTION_HIGH", high);
      std::string msg;
      REQUIRE(error_of([] { (void)pdt::EngineOptions::from_environment(); }, &msg) == pdt::ErrorCode::invalid_argument);
      INFO(msg);
      CHECK(msg.find("PDT_CONTENTION_LOW=") != std::string::npos);
      CHECK(msg.find("PDT_CONTENTION_HIGH=") != std::string::npos);
      CHECK((msg.find("(not set: the default)") != std::string::npos) == (!low || !high));
    }
    EnvGuard env;  // equal is allowed
    env.set("PDT_CONTENTION_LOW", "0.9");
    CHECK(pdt::EngineOptions::from_environment().contention_low == 0.9);
  }
}

TEST_CASE("engine: the constructor checks its options and domain", "[engine]") {
  pdt::Triangulation t;
  const pdt::Box unit{{0, 0, 0}, {1, 1, 1}};
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::EngineOptions o = options_with(2);
    o.contention_low = 0.9;
    o.contention_high = 0.5;
    REQUIRE(error_of([&] { pdt::Engine e(t, unit, o); }) == pdt::ErrorCode::invalid_argument);
    o = options_with(2);
    o.contention_high = 1.5;
    REQUIRE(error_of([&] { pdt::Engine e(t, unit, o); }) == pdt::ErrorCode::invalid_argument);
    o = options_with(2);
    o.contention_low = -0.1;
    REQUIRE(error_of([&] { pdt::Engine e(t, unit, o); }) == pdt::ErrorCode::invalid_argument);
    // Too many workers, by either name: the message names the field set.
    for (const bool old_name : {false, true}) {
      pdt::EngineOptions w;
      (old_name ? w.threads : w.workers) = pdt::EngineOptions::max_workers + 1;
      std::string what;
      try {
        pdt::Engine e(t, unit, w);
      } catch (const pdt::Error& err) {
        what = err.what();
        CHECK(err.code() == pdt::ErrorCode::invalid_argument);
      }
      INFO(what);
      CHECK(what.rfind(old_name ? "threads (the deprecated name of workers) must be at most" : "workers must be at most",
                       0) == 0);
    }

    for (pdt::Box b : {pdt::Box{{0, 0, 1}, {1, 1, 0}}, pdt::Box{{2, 0, 0}, {1, 1, 1}}, pdt::Box{{0, 3, 0}, {1, 1, 1}},
                       pdt::Box{{0, 0, 0}, {std::numeric_limits<double>::quiet_NaN(), 1, 1}},
                       pdt::Box{{0, 0, 0}, {std::numeric_limits<double>::infinity(), 1, 1}}}) {
      REQUIRE(error_of([&] { pdt::Engine e(t, b, options_with(2)); }) == pdt::ErrorCode::invalid_argument);
    }
    // A degenerate (flat) box is allowed: lo == hi on an axis.
    REQUIRE_FALSE(error_of([&] { pdt::Engine e(t, pdt::Box{{0, 0, 0}, {1, 1, 0}}, options_with(2)); }));

    for (auto [threads, blocks, want_blocks] : {std::tuple{1u, 0u, 8u}, std::tuple{5u, 0u, 8u},
                                                std::tuple{16u, 0u, 11u}, std::tuple{3u, 7u, 7u},
                                                std::tuple{16u, 1u, 1u}}) {
      pdt::EngineOptions oo = options_with(threads);
      oo.blocks_per_axis = blocks;
      pdt::Engine e(t, unit, oo);
      REQUIRE(e.workers() == threads);
      REQUIRE(e.blocks_per_axis() == want_blocks);
      REQUIRE(e.options().workers == threads);
      REQUIRE(e.stats().workers.size() == threads);
    }
  });
  REQUIRE(t.number_of_vertices() == 0);
}

TEST_CASE("engine: unusual block layouts still give the exact result", "[engine][tsan]") {
  // One block for 8 workers (7 idle), more blocks than needed, a flat domain axis.
  const pdt::OpStream s = generated(pdt::Distribution::uniform, scaled(2000, 300), 0.3, pdt::RemovalOrder::interleaved, 9);
  for (unsigned blocks : {1u, 9u})
  for (bool stealing : {true, false}) {
    INFO(blocks << " blocks per axis, stealing " << stealing);
    pdt::EngineOptions o = options_with(8);
    o.blocks_per_axis = blocks;
    o.contention_window = 4;
    o.stealing = stealing;
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, o);
    REQUIRE(run.blocks == blocks);
    require_stats(run, s.ops.size(), 8);
    if (blocks == 1 && !stealing) {
      // Everything goes to worker 0, whose home the one block is.
      REQUIRE(run.stats.workers[0].completed == s.ops.size());
    }
    if (!stealing) REQUIRE(run.stats.total().steals == 0);
    require_result(t, s);
  }
}

TEST_CASE("engine: NonEmptyBlocks finds the nearest marked block on either side", "[engine]") {
  // Sizes around the word boundaries; a reference set checked against every query.
  for (std::uint32_t count : {1u, 63u, 64u, 65u, 200u}) {
    pdt::detail::NonEmptyBlocks marks(count);
    std::vector<std::atomic<std::uint32_t>> queued(count);
    std::vector<bool> ref(count, false);
    std::mt19937 rng(count);
    for (int round = 0; round < 200; ++round) {
      const std::uint32_t i = rng() % count;
      if (rng() % 3) {
        queued[i].store(1);
        marks.mark(i);
        ref[i] = true;
      } else {
        queued[i].store(0);
        marks.clear_if_empty(i, queued[i]);
        ref[i] = false;
      }
      for (std::uint32_t from = 0; from <= count; ++from) {
        std::uint32_t want_next = count;
        for (std::uint32_t k = from; k < count; ++k)
          if (ref[k]) { want_next = k; break; }
        REQUIRE(marks.next(from, count) == want_next);
        std::int64_t want_prev = -1;
        for (std::int64_t k = std::int64_t{from} - 1; k >= 0; --k)
          if (ref[static_cast<std::size_t>(k)]) { want_prev = k; break; }
        REQUIRE(marks.prev(std::int64_t{from} - 1) == want_prev);
      }
    }
    // A clear that finds work come in meanwhile keeps the mark.
    queued[0].store(1);
    marks.mark(0);
    marks.clear_if_empty(0, queued[0]);
    REQUIRE(marks.marked(0));
  }
}

TEST_CASE("engine: the most workers the engine accepts, on this machine's few cores", "[engine][tsan]") {
  // 4096 workers cut the domain into 64^3 blocks; idle workers find work
  // through NonEmptyBlocks (scanning every block took 25 s for 2000 points).
  const pdt::OpStream s = generated(pdt::Distribution::uniform, scaled(2000, 300), 0.3, pdt::RemovalOrder::interleaved, 4);
  pdt::Triangulation t;
  const EngineRun run = replay_engine(t, s, *s.box, options_with(4096));
  REQUIRE(run.blocks == 64);
  require_stats(run, s.ops.size(), 4096);
  require_result(t, s);
}

// =============================================================================
// 6. Determinism
// =============================================================================
TEST_CASE("engine: 1 and 16 workers give identical tetrahedra", "[engine][tsan]") {
  for (pdt::Distribution dist : {pdt::Distribution::normal, pdt::Distribution::grid}) {
    const pdt::OpStream s = generated(dist, scaled(4000, 500), 0.3, pdt::RemovalOrder::interleaved, 123);
    pdt::Triangulation one, many;
    replay_engine(one, s, *s.box, options_with(1));
    replay_engine(many, s, *s.box, options_with(16));
    std::vector<Point3> pts;
    for (const auto& op : s.ops)
      if (op.kind == pdt::Operation::Kind::insert) pts.push_back(op.point);
    const PointIndex idx = make_point_index(pts);
    const TetList a = canonical_tets(one, idx), b = canonical_tets(many, idx);
    INFO(pdt::to_string(dist));
    REQUIRE(!a.empty());
    const bool same = a == b;
    INFO((same ? std::string() : describe_mismatch(b, a, pts)));
    REQUIRE(same);
    REQUIRE(surviving_points(one).size() == surviving_points(many).size());
    require_valid(many);
  }
}

// =============================================================================
// 7. After the engine
// =============================================================================
TEST_CASE("engine: the triangulation is usable sequentially after the engine is gone", "[engine][tsan]") {
  const pdt::OpStream s = generated(pdt::Distribution::uniform, scaled(3000, 400), 0.3, pdt::RemovalOrder::interleaved, 5);
  pdt::Triangulation t;
  replay_engine(t, s, *s.box, options_with(16));
  require_result(t, s);

  // Continue sequentially: insert more (also outside the old domain), remove a third.
  std::vector<Point3> expected = survivors(s);
  std::vector<Point3> more = random_points(scaled(2000, 300), 6, -0.5, 1.5);
  for (const auto& p : more) {
    const pdt::InsertResult r = t.insert(p);
    REQUIRE(r.inserted);
    REQUIRE(t.point(r.vertex) == p);
  }
  expected.insert(expected.end(), more.begin(), more.end());
  require_valid(t);
  std::vector<pdt::VertexId> vs = t.vertices();
  shuffle(vs, 8);
  vs.resize(vs.size() / 3);
  std::uint64_t removals = 0;
  for (pdt::VertexId v : vs) {
    const Point3 p = t.point(v);
    const std::uint32_t m = t.multiplicity(v);
    for (std::uint32_t k = 0; k < m; ++k) t.remove(v), ++removals;
    REQUIRE_FALSE(t.is_vertex(v));
    expected.erase(std::remove(expected.begin(), expected.end(), p), expected.end());
  }
  require_valid(t);
  require_same_as_cgal(t, expected);
  // The workers' statistics were folded into the triangulation's.
  REQUIRE(t.stats().insertions == s.insert_count() + more.size());
  REQUIRE(t.stats().removals == s.remove_count() + removals);

  // And a second engine over the same triangulation, then sequential again.
  tbb::task_arena arena(2);
  std::vector<Point3> extra = random_points(scaled(1000, 200), 9, -0.5, 1.5);
  arena.execute([&] {
    pdt::Engine e(t, {{-0.5, -0.5, -0.5}, {1.5, 1.5, 1.5}}, options_with(4));
    for (const auto& p : extra) e.insert(p, {});
  });  // destroyed without an explicit drain: the destructor drains
  expected.insert(expected.end(), extra.begin(), extra.end());
  require_valid(t);
  require_same_as_cgal(t, expected);
  for (pdt::VertexId v : t.vertices()) t.remove(v);  // all the way down, sequentially
  REQUIRE(t.number_of_vertices() == 0);
  REQUIRE(t.dimension() == -1);
  require_valid(t);
}

TEST_CASE("engine: skewed streams give CGAL's triangulation with 1 to 16 workers, stealing on and off",
          "[engine][balance][tsan]") {
  // Work that concentrates (a corner, a Kuzmin cluster) or moves (fronts
  // along each axis): blocks change hands between workers all the time.
  const std::size_t n = scaled(4000, 500);
  for (pdt::Distribution dist : {pdt::Distribution::corner, pdt::Distribution::kuzmin, pdt::Distribution::front_x,
                                 pdt::Distribution::front_y, pdt::Distribution::front_z}) {
    const pdt::OpStream s = generated(dist, n, 0.3, pdt::RemovalOrder::interleaved, 5);
    REQUIRE(s.box.has_value());
    pdt::Triangulation seq;
    replay_sequential(seq, s);
    for (unsigned threads : {1u, 2u, 3u, 8u, 16u}) {
      for (bool stealing : {true, false}) {
        INFO(pdt::to_string(dist) << ", " << n << " points, " << threads << " workers, stealing " << stealing);
        pdt::EngineOptions o = options_with(threads);
        o.stealing = stealing;
        pdt::Triangulation t;
        const EngineRun run = replay_engine(t, s, *s.box, o, ArenaMode::inside, 4);
        require_stats(run, s.ops.size(), threads);
        if (!stealing) {
          for (const pdt::WorkerStats& w : run.stats.workers) REQUIRE(w.steals == 0);
        }
        require_result(t, s, &seq);
      }
    }
  }
}

TEST_CASE("engine: a recut gives each block an equal share of the work, and routes by the cut",
          "[engine][balance]") {
  const pdt::Box box{{0, 0, 0}, {1, 1, 1}};
  pdt::detail::Partition part(box, 6, 2);  // 216 blocks
  REQUIRE(part.blocks() == 216);
  // At the start: equal volumes, so uniform points spread evenly.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<std::size_t> count(part.blocks());
  for (int i = 0; i < 216000; ++i) ++count[part.block_of({u(rng), u(rng), u(rng)})];
  for (std::size_t c : count) REQUIRE((c > 700 && c < 1300));
  // A Kuzmin cluster crowds a few blocks; cut at its keys' quantiles, every
  // block gets about the same share.
  pdt::GenerateOptions g;
  g.points = 50000;
  g.dist = pdt::Distribution::kuzmin;
  std::vector<pdt::Point3> pts;
  for (const pdt::Operation& op : pdt::generate(g).ops) pts.push_back(op.point);
  std::fill(count.begin(), count.end(), 0);
  for (const pdt::Point3& p : pts) ++count[part.block_of(p)];
  REQUIRE(*std::max_element(count.begin(), count.end()) > 2000);  // before: a hot block
  std::vector<std::uint64_t> keys;
  for (const pdt::Point3& p : pts) keys.push_back(part.key_of(p));
  std::sort(keys.begin(), keys.end());
  part.recut(keys);
  std::fill(count.begin(), count.end(), 0);
  for (const pdt::Point3& p : pts) {
    const std::uint32_t b = part.block_of(p);
    ++count[b];
    REQUIRE(part.block_of_key(part.key_of(p)) == b);
  }
  const double fair = double(pts.size()) / part.blocks();
  for (std::size_t c : count) REQUIRE(double(c) < 2 * fair);
  // Keys out of the box, and the ends of the curve, still land in a block.
  REQUIRE(part.block_of({-1e300, 2, 0.5}) < part.blocks());
  REQUIRE(part.block_of_key(0) == 0);
  REQUIRE(part.block_of_key(pdt::detail::Partition::key_end - 1) == part.blocks() - 1);
}

TEST_CASE("engine: recuts happen when the work piles up in one block, and give CGAL's triangulation",
          "[engine][balance][tsan]") {
  // Every point in the corner [0, 0.45]^3, with 2 blocks per axis: all the
  // work lands in one block. The first callback holds its worker until the
  // whole stream is queued; then the two workers running find that block held
  // by the other with thousands of operations waiting, and one re-cuts.
  const std::size_t n = scaled(20000, 8000);
  const pdt::OpStream s = generated(pdt::Distribution::corner, n, 0.3, pdt::RemovalOrder::interleaved, 9);
  pdt::Triangulation seq;
  replay_sequential(seq, s);
  // Whether a worker finds the block held at a moment when it may re-cut is
  // up to the scheduler: with rebalancing on, up to three runs, each checked
  // whole, and at least one must re-cut (one run in about a dozen full test
  // runs under -j2 did not).
  for (int run = 0; run < 4; ++run) {
    const bool rebalance = run < 3;
    INFO("rebalance " << rebalance << ", run " << run);
    pdt::EngineOptions o = options_with(4);
    o.blocks_per_axis = 2;
    o.rebalance = rebalance;
    pdt::Triangulation t;
    std::atomic<bool> queued_all{false}, first{true};
    std::atomic<std::uint64_t> failed{0};
    std::mutex threads_mutex;
    std::set<std::thread::id> threads;  // that ran the workers
    pdt::EngineStats stats;
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::Engine e(t, *s.box, o);
      const pdt::Engine::Callback done = [&](const pdt::OpResult& r) {
        if (r.error) failed.fetch_add(1);
        {
          std::lock_guard lock(threads_mutex);
          threads.insert(std::this_thread::get_id());
        }
        if (first.exchange(false))
          while (!queued_all.load()) std::this_thread::yield();
      };
      for (const pdt::Operation& op : s.ops) {
        if (op.kind == pdt::Operation::Kind::insert)
          (void)e.insert(op.point, done);
        else
          e.remove_insertion(op.target, done);
      }
      queued_all.store(true);
      e.drain();
      stats = e.stats();
    });
    REQUIRE(failed.load() == 0);
    REQUIRE(stats.total().completed == s.ops.size());
    require_result(t, s, &seq);
    if (!rebalance) {
      REQUIRE(stats.recuts == 0);
    } else if (threads.size() < 2) {
      WARN("only one thread ran the workers (TBB gave the arena no worker thread): no recut is possible");
      run = 2;  // on to the run without rebalancing
    } else if (stats.recuts > 0) {
      run = 2;
    } else {
      REQUIRE(run < 2);  // the third run without a recut fails
    }
  }
}

TEST_CASE("engine: one worker's walks stay short where its blocks fill a cluster late", "[engine][tsan]") {
  // Half the points uniform in the unit cube, half in a cube of side 1e-3,
  // interleaved. One worker serves the blocks in turn, so the cluster's block
  // fills between two rebuilds of the grid (as the vertex count doubles),
  // whose equal slots held it in one: 34 steps per insertion here (66 at
  // 400k points; 8 now). Long walks now rebuild it early, as a tree that
  // follows the vertices.
  const std::size_t n = scaled(40000, 10000);
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts{{0, 0, 0}, {1, 1, 1}};
  for (std::size_t i = 0; i < n; ++i)
    pts.push_back(i % 2 ? Point3{u(rng), u(rng), u(rng)} : Point3{0.3 + 1e-3 * u(rng), 0.3 + 1e-3 * u(rng), 0.3 + 1e-3 * u(rng)});
  const double steps = engine_walk_steps(pts, 1, 1);
  INFO("walk steps per insertion " << steps);
  CHECK(steps < 15);
}

TEST_CASE("engine: walks stay short in clusters far smaller than the box", "[engine][tsan]") {
  // Two clusters of side 1e-4 in the unit cube, submitted singly in random
  // order. Equal slots over the box held each cluster in a slot or two, and
  // every walk started at the slot's vertex, across its cluster: 65 steps per
  // insertion at 50k points, 104 at 200k, with 1 or 2 workers (the
  // sequential kernel's tree: 7). The rebuilds now see the crowded slots and
  // cut the crowded slots again where the clusters are (build_split).
  const std::size_t n = scaled(40000, 10000);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts{{0, 0, 0}, {1, 1, 1}};
  for (std::size_t i = 0; i < n; ++i) {
    const double c = i % 2 ? 0.2 : 0.7;
    pts.push_back({c + 1e-4 * u(rng), c + 1e-4 * u(rng), c + 1e-4 * u(rng)});
  }
  for (unsigned workers : {1u, 2u}) {
    const double steps = engine_walk_steps(pts, workers, 2);
    INFO(workers << " workers, walk steps per insertion " << steps);
    CHECK(steps < 20);
  }
}

TEST_CASE("engine: an insert_batch piled in one block is re-cut too, and gives CGAL's triangulation",
          "[engine][balance][tsan]") {
  // insert_batch queues runs of up to 256 points as one record each; the
  // recut weighs a run by its points, so the cut follows the points.
  pdt::GenerateOptions g;
  g.points = scaled(20000, 8000);
  g.dist = pdt::Distribution::corner;
  const pdt::OpStream s = pdt::generate(g);
  std::vector<pdt::Point3> pts;
  for (const pdt::Operation& op : s.ops) pts.push_back(op.point);
  pdt::EngineOptions o = options_with(4);
  o.blocks_per_axis = 2;
  pdt::Triangulation t;
  pdt::EngineStats stats;
  std::mutex threads_mutex;
  std::set<std::thread::id> threads;  // that ran the workers
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::Engine e(t, *s.box, o);
    (void)e.insert_batch(pts, [&](const pdt::OpResult&) {
      std::lock_guard lock(threads_mutex);
      threads.insert(std::this_thread::get_id());
    });
    e.drain();
    stats = e.stats();
  });
  REQUIRE(stats.total().completed == pts.size());
  if (threads.size() < 2)
    WARN("only one thread ran the workers (TBB gave the arena no worker thread): no recut is possible");
  else
    CHECK(stats.recuts > 0);
  require_result(t, s);
}

TEST_CASE("engine: the skewed generators put their points where they say", "[engine][balance]") {
  pdt::GenerateOptions g;
  g.points = 5000;
  g.dist = pdt::Distribution::corner;
  for (const pdt::Operation& op : pdt::generate(g).ops) {
    REQUIRE(op.point.x <= 0.45);
    REQUIRE(op.point.y <= 0.45);
    REQUIRE(op.point.z <= 0.45);
  }
  g.dist = pdt::Distribution::kuzmin;
  std::size_t near = 0;
  for (const pdt::Operation& op : pdt::generate(g).ops) {
    const double dx = op.point.x - 0.5, dy = op.point.y - 0.5, dz = op.point.z - 0.5;
    near += dx * dx + dy * dy + dz * dz < 0.1 * 0.1;
  }
  CHECK(near > 5000 / 2);  // a cluster: most points within 0.1 of the centre
  g.dist = pdt::Distribution::clusters;
  const pdt::OpStream clustered = pdt::generate(g);
  REQUIRE(clustered.ops.size() == 5000);
  std::size_t in_cube[2] = {0, 0};
  for (std::size_t i = 0; i < clustered.ops.size(); ++i) {
    const Point3& p = clustered.ops[i].point;
    REQUIRE(p.x >= 0);
    REQUIRE(p.x <= 1);
    for (int c = 0; c < 2; ++c) {
      const double lo = c ? 0.7 : 0.2;
      if (p.x >= lo && p.x <= lo + 1e-4 && p.y >= lo && p.y <= lo + 1e-4 && p.z >= lo && p.z <= lo + 1e-4) {
        ++in_cube[c];
        REQUIRE(i % 2 == 1);  // every other point
      }
    }
  }
  CHECK(in_cube[0] == 1250);
  CHECK(in_cube[1] == 1250);
  CHECK(pdt::parse_distribution("clusters") == pdt::Distribution::clusters);
  int axis = 0;
  for (pdt::Distribution d : {pdt::Distribution::front_x, pdt::Distribution::front_y, pdt::Distribution::front_z}) {
    g.dist = d;
    const pdt::OpStream s = pdt::generate(g);
    auto key = [axis](const pdt::Point3& p) { return axis == 0 ? p.x : axis == 1 ? p.y : p.z; };
    for (std::size_t i = 1; i < s.ops.size(); ++i) REQUIRE(key(s.ops[i - 1].point) <= key(s.ops[i].point));
    ++axis;
  }
}

TEST_CASE("engine: storage follows the live mesh when workers free what others allocate", "[engine][memory]") {
  // The mesh is emptied after every round. A worker's pool used to keep what
  // it freed while another carved new storage for what it made, and a new
  // engine's workers carved new storage while the triangulation's own pool
  // held every id the last engine freed (10 engines in turn: the cell id bound
  // grew 9x). The surplus now goes to shared spare segments.
  auto round_of = [](pdt::Engine& e, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<pdt::Engine::Ticket> tickets;
    const std::size_t n = pdt_test::scaled(5000, 1000);
    for (std::size_t i = 0; i < n; ++i) tickets.push_back(e.insert({u(rng), u(rng), u(rng)}, {}));
    e.drain();
    e.remove_insertions(tickets);
    e.drain();
  };
  for (const auto& config : {std::pair{2u, false}, {4u, false}, {2u, true}, {4u, true}}) {
    const unsigned workers = config.first;  // not a structured binding: lambdas capture it (Clang 14)
    const bool in_turn = config.second;
    INFO(workers << " workers, " << (in_turn ? "engines in turn" : "one engine"));
    pdt::Triangulation t;
    tbb::task_arena arena(2);
    std::mt19937_64 rng(workers);
    std::uint32_t cells_first = 0, verts_first = 0;
    if (!in_turn) {
      arena.execute([&] {
        pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(workers));
        for (int round = 0; round < (pdt_test::kTsan ? 6 : 30); ++round) {
          round_of(e, rng);
          REQUIRE(t.number_of_vertices() == 0);
          if (round == 0) cells_first = t.cell_id_bound(), verts_first = t.vertex_id_bound();
        }
      });
    }
    if (in_turn) {
      for (int round = 0; round < (pdt_test::kTsan ? 4 : 10); ++round) {
        arena.execute([&] {
          pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, options_with(workers));
          round_of(e, rng);
        });
        REQUIRE(t.number_of_vertices() == 0);
        if (round == 0) cells_first = t.cell_id_bound(), verts_first = t.vertex_id_bound();
      }
    }
    INFO("cell id bound " << cells_first << " -> " << t.cell_id_bound() << ", vertex id bound " << verts_first
                          << " -> " << t.vertex_id_bound());
    // What a worker may keep: under two segments in its list and a chunk's
    // fresh ids, of each kind.
    CHECK(t.cell_id_bound() <= cells_first + workers * 3 * 1536);
    CHECK(t.vertex_id_bound() <= verts_first + workers * 3 * 256);
    // The triangulation goes on after the engines: their pools were merged.
    std::uniform_real_distribution<double> u(0, 1);
    for (int i = 0; i < 100; ++i) t.insert({u(rng), u(rng), u(rng)});
    require_valid(t);
  }
}
