// SPDX-License-Identifier: MIT
// Exception safety (built against pdt_fault: libpdt with its allocation-
// failure injection points armed; lib/fault_injection.hpp). An operation that
// meets a failed allocation either completes or changes nothing: for every
// kind of operation, the k-th allocation point is made to fail, for k = 0, 1,
// 2, ... until the operation gets through, and after each failure the
// triangulation must validate and be exactly what it was.
#include <oneapi/tbb/task_arena.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <new>
#include <set>
#include <string>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/point_sets.hpp"
#include "fault_injection.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/triangulation.hpp"

using namespace pdt_test;
using pdt::Point3;
namespace fault = pdt::detail::fault;

namespace {

// The state an operation must leave untouched when it fails.
struct Snapshot {
  int dimension;
  std::size_t vertices, cells;
  TetList tets;
  std::vector<std::pair<Point3, std::uint32_t>> multiplicities;
};

Snapshot snapshot(const pdt::Triangulation& t, const PointIndex& index) {
  Snapshot s{t.dimension(), t.number_of_vertices(), t.number_of_cells(), canonical_tets(t, index), {}};
  for (pdt::VertexId v : t.vertices()) s.multiplicities.emplace_back(t.point(v), t.multiplicity(v));
  return s;
}

void require_unchanged(const pdt::Triangulation& t, const PointIndex& index, const Snapshot& before) {
  require_valid(t);
  const Snapshot now = snapshot(t, index);
  REQUIRE(now.dimension == before.dimension);
  REQUIRE(now.vertices == before.vertices);
  REQUIRE(now.cells == before.cells);
  REQUIRE((now.tets == before.tets));
  REQUIRE((now.multiplicities == before.multiplicities));
}

// Runs op with the k-th fault point failing, k = 0, 1, ...; after every
// failure the triangulation must be as it was. Returns how many failures
// were injected before op got through.
// With `first` given, only the first `first` points are failed; then op
// runs without failures.
std::uint64_t fail_each_point(pdt::Triangulation& t, const std::vector<Point3>& known, const std::function<void()>& op,
                              std::set<std::string>* sites = nullptr, std::uint64_t first = 10000) {
  const PointIndex index = make_point_index(known);
  const Snapshot before = snapshot(t, index);
  for (std::uint64_t k = 0;; ++k) {
    if (first < 10000 && k == first) {
      op();
      return k;
    }
    REQUIRE(k < 10000);
    fault::arm(k);
    bool failed = false;
    try {
      op();
    } catch (const std::bad_alloc&) {
      failed = true;
    }
    fault::disarm();
    if (!failed) return k;
    if (sites) sites->insert(fault::last_failed_site());
    INFO("failure injected at point " << k << " (" << fault::last_failed_site() << ")");
    require_unchanged(t, index, before);
  }
}

}  // namespace

TEST_CASE("fault: every allocation an insertion or a removal makes may fail, changing nothing", "[fault]") {
  std::vector<Point3> pts = random_points(400, 1);
  pdt::Triangulation t;
  t.insert_batch(pts);
  std::vector<Point3> known = pts;
  const Point3 extra{0.31, 0.62, 0.47};
  known.push_back(extra);

  SECTION("insert in 3D") {
    const std::uint64_t k = fail_each_point(t, known, [&] { t.insert(extra); });
    REQUIRE(k > 0);  // the kernel does reach allocation points
    require_same_as_cgal(t, known);
  }
  SECTION("insert in 3D, reporting to a hook (cells made and destroyed)") {
    std::size_t reported = 0;
    t.set_change_hook([&](const pdt::Changes& c) { reported = c.created.size() + c.destroyed.size(); }, true);
    fail_each_point(t, known, [&] { t.insert(extra); });
    REQUIRE(reported > 0);
    require_same_as_cgal(t, known);
  }
  SECTION("remove in 3D") {
    const pdt::VertexId v = t.nearest_vertex({0.5, 0.5, 0.5});
    const Point3 p = t.point(v);
    fail_each_point(t, known, [&] { t.remove(v); });
    std::vector<Point3> left;
    for (const Point3& q : pts)
      if (!(q == p)) left.push_back(q);
    require_same_as_cgal(t, left);
  }
}

TEST_CASE("fault: an insertion whose new vertex needs a fresh chunk of ids may fail there, changing nothing",
          "[fault]") {
  // Vertex ids come in chunks (256 at a time): inserted one by one past a
  // chunk's end, one insertion takes a fresh chunk, after its conflict zone is
  // found and marked. A failure there must leave no cell marked (validate
  // checks), else the next search takes a marked cell for its own zone's.
  std::vector<Point3> pts = random_points(300, 11);
  pdt::Triangulation t;
  t.insert_batch(pts);
  std::vector<Point3> known = pts;
  std::set<std::string> sites;
  const std::vector<Point3> extras = random_points(240, 12);
  for (std::size_t i = 0; i < extras.size(); ++i) {
    known.push_back(extras[i]);
    if (i < 200)  // 500 vertices: the second chunk's end (ids 257-512) is near
      t.insert(extras[i]);
    else
      fail_each_point(t, known, [&] { t.insert(extras[i]); }, &sites);
  }
  REQUIRE(sites.count("vertex chunk") == 1);  // the case this test is for was reached
  require_same_as_cgal(t, known);
}

TEST_CASE("fault: the centre of 510 cospherical points: a huge cavity and a large link fail cleanly", "[fault]") {
  // The centre conflicts with every cell (its cavity is the whole mesh, past
  // what a free list keeps: reserved spare segments), and its removal puts
  // the 510-vertex link in spatial order before triangulating it. The
  // insertion and the removal reach thousands of allocation points each (the
  // removal's mostly in the small triangulation): the first 400 and 200 are
  // failed in turn; the removal's include the link's ordering ('link order',
  // checked below).
  std::vector<Point3> sphere = cospherical(2025);
  shuffle(sphere, 111);
  pdt::Triangulation t;
  t.insert_batch(sphere);
  const Point3 centre{0, 0, 0};
  t.remove(t.insert(centre).vertex);  // leaves the freed ids in the spare stack
  std::vector<Point3> known = sphere;
  known.push_back(centre);
  std::set<std::string> sites;
  fail_each_point(t, known, [&] { t.insert(centre); }, &sites, 400);
  require_same_as_cgal(t, known);
  const pdt::VertexId v = t.nearest_vertex(centre);
  REQUIRE(t.point(v) == centre);
  fail_each_point(t, known, [&] { t.remove(v); }, &sites, 200);
  require_same_as_cgal(t, sphere);
  INFO("sites failed: " << sites.size());
  REQUIRE(sites.count("link order") == 1);
}

TEST_CASE("fault: changes of dimension fail cleanly too", "[fault]") {
  // A plane of points, then an apex: the first tetrahedra (build_3d); then
  // the apex's removal drops back to the plane (drop_to_flat).
  std::vector<Point3> plane;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j) plane.push_back({i * 0.1 + 0.01 * j, j * 0.1, 0.5});
  std::vector<Point3> known = plane;
  const Point3 apex{0.3, 0.3, 0.9};
  known.push_back(apex);
  pdt::Triangulation t;
  for (const Point3& p : plane) t.insert(p);
  REQUIRE(t.dimension() == 2);
  fail_each_point(t, known, [&] { t.insert({0.35, 0.25, 0.5}); });  // one more in the plane
  known.push_back({0.35, 0.25, 0.5});
  fail_each_point(t, known, [&] { t.insert(apex); });
  REQUIRE(t.dimension() == 3);
  const pdt::VertexId a = t.nearest_vertex(apex);
  fail_each_point(t, known, [&] { t.remove(a); });
  REQUIRE(t.dimension() == 2);
  const pdt::VertexId b = t.nearest_vertex(plane[10]);
  fail_each_point(t, known, [&] { t.remove(b); });
  require_valid(t);
}

TEST_CASE("fault: the engine reports failed allocations per operation and keeps working", "[fault]") {
  // Failures anywhere: at submission (the call throws, nothing is submitted),
  // in an operation (its OpResult carries the error, nothing changed), in a
  // global step or the grid's growth (the world restarts). Whatever
  // succeeded must be exactly the triangulation at the end.
  pdt::Triangulation t;
  const std::vector<Point3> pts = random_points(3000, 7);
  std::mutex m;
  std::vector<Point3> inserted;                      // insertions that succeeded
  std::vector<pdt::Engine::Ticket> tickets_done;     // and their tickets
  std::multiset<std::size_t> removed_indices;
  std::atomic<int> failed_ops{0}, refused{0};
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::EngineOptions o;
    o.workers = 4;
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
    std::vector<pdt::Engine::Ticket> ticket_of(pts.size(), ~std::uint64_t{0});
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (i % 50 == 0) fault::arm(i % 7 * 3);  // a failure soon, somewhere
      try {
        ticket_of[i] = e.insert(pts[i], [&, i](const pdt::OpResult& r) {
          std::lock_guard lock(m);
          if (r.error)
            failed_ops.fetch_add(1);
          else if (r.insert.inserted)
            inserted.push_back(pts[i]);
        });
      } catch (const std::bad_alloc&) {
        refused.fetch_add(1);
      }
    }
    fault::disarm();
    e.drain();
    // Undo some, with failures again.
    std::vector<std::pair<pdt::Engine::Ticket, Point3>> undo;
    for (std::size_t i = 0; i < pts.size(); i += 3)
      if (ticket_of[i] != ~std::uint64_t{0}) undo.emplace_back(ticket_of[i], pts[i]);
    std::vector<Point3> undone;
    for (std::size_t k = 0; k < undo.size(); ++k) {
      if (k % 40 == 0) fault::arm(k % 5 * 2);
      try {
        e.remove_insertion(undo[k].first, [&, p = undo[k].second](const pdt::OpResult& r) {
          std::lock_guard lock(m);
          if (r.error)
            failed_ops.fetch_add(1);
          else
            undone.push_back(p);
        });
      } catch (const std::bad_alloc&) {
        refused.fetch_add(1);
      } catch (const pdt::Error&) {
        // The insertion had failed: nothing to undo.
      }
    }
    fault::disarm();
    e.drain();
    for (const Point3& p : undone) {
      auto it = std::find(inserted.begin(), inserted.end(), p);
      REQUIRE(it != inserted.end());
      inserted.erase(it);
    }
  });
  INFO(failed_ops.load() << " operations failed, " << refused.load() << " submissions refused");
  REQUIRE(failed_ops.load() + refused.load() > 0);  // the injection did hit
  require_valid(t);
  require_same_as_cgal(t, inserted);
}

TEST_CASE("fault: an engine's insert_batch meeting failed allocations mid-way completes, and the rest is exact",
          "[fault]") {
  // The batch is queued as runs of points; a worker makes a record for each
  // point as it serves it. Allocations failing then (a record slab, a cell
  // chunk, a ticket shard...) fail single points (their OpResult says so)
  // and never stall the batch.
  const std::vector<Point3> pts = random_points(4000, 11);
  int failed_in_all = 0;
  for (std::uint64_t countdown : {0u, 1u, 2u, 5u, 13u, 40u}) {
    INFO("countdown " << countdown);
    pdt::Triangulation t;
    std::mutex m;
    std::vector<Point3> inserted;
    std::atomic<int> failed{0};
    tbb::task_arena arena(2);
    arena.execute([&] {
      pdt::EngineOptions o;
      o.workers = 3;
      pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
      // A fresh engine numbers its insertions from 0: ticket i is pts[i].
      const pdt::Engine::Ticket first = e.insert_batch(pts, [&](const pdt::OpResult& r) {
        std::lock_guard lock(m);
        if (r.error)
          failed.fetch_add(1);
        else if (r.insert.inserted)
          inserted.push_back(pts[r.ticket]);
      });
      REQUIRE(first == 0);
      fault::arm(countdown);
      e.drain();
      fault::disarm();
    });
    REQUIRE(inserted.size() + static_cast<std::size_t>(failed.load()) == pts.size());
    require_valid(t);
    require_same_as_cgal(t, inserted);
    failed_in_all += failed.load();
  }
  REQUIRE(failed_in_all > 0);  // the injection did hit
}


TEST_CASE("fault: remove_insertions meeting a failed allocation submits nothing and gives every claim back",
          "[fault]") {
  // The records of the undos come from the engine's record pool, which grows
  // by slabs: undoing more insertions than it holds reaches fault points.
  // A failure there must leave the batch unsubmitted and every ticket
  // undoable again; the same call then succeeds.
  const std::vector<Point3> pts = random_points(5000, 13);
  pdt::Triangulation t;
  int failures = 0;
  tbb::task_arena arena(2);
  arena.execute([&] {
    pdt::EngineOptions o;
    o.workers = 3;
    pdt::Engine e(t, {{0, 0, 0}, {1, 1, 1}}, o);
    const pdt::Engine::Ticket first = e.insert_batch(pts);
    e.drain();
    REQUIRE(t.number_of_vertices() == pts.size());
    std::vector<pdt::Engine::Ticket> batch(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) batch[i] = first + i;
    std::atomic<std::size_t> undone{0}, failed{0};
    auto count = [&](const pdt::OpResult& r) { (r.error ? failed : undone).fetch_add(1); };
    for (std::uint64_t k = 0;; ++k) {
      REQUIRE(k < 100);
      fault::arm(k);
      bool threw = false;
      try {
        e.remove_insertions(batch, count);
      } catch (const std::bad_alloc&) {
        threw = true;
      }
      fault::disarm();
      e.drain();
      if (!threw) break;
      ++failures;
      INFO("failure at point " << k << " (" << fault::last_failed_site() << ")");
      REQUIRE(undone.load() == 0);
      REQUIRE(failed.load() == 0);
      REQUIRE(t.number_of_vertices() == pts.size());
    }
    // The call that succeeded left the countdown armed until it returned: a
    // worker that started meanwhile may have met it (its undo then failed,
    // changing nothing; slow builds such as TSan's show it).
    REQUIRE(undone.load() + failed.load() == pts.size());
    REQUIRE(t.number_of_vertices() == failed.load());
  });
  REQUIRE(failures > 0);  // the injection did hit
  require_valid(t);
}
