// SPDX-License-Identifier: MIT
#include "refine/refiner.hpp"

#include <oneapi/tbb/concurrent_queue.h>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/parallel_reduce.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <coroutine>
#include <cstdio>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <thread>
#include <unordered_map>
#include <vector>

#include "refine/quality.hpp"
#include "refine/samples.hpp"

namespace pdt_refine {

namespace {

using pdt::Point3;

// The refiner's own data per cell: the incarnation of the live cell with
// that id (0: none), written by the change hook inside the operation that
// makes or deletes the cell. Chunks of 2^16 ids, allocated when first needed.
class CellTable {
 public:
  CellTable() : chunks_(std::make_unique<std::atomic<Chunk*>[]>(max_chunks)) {}
  ~CellTable() {
    for (std::size_t i = 0; i < max_chunks; ++i) delete chunks_[i].load();
  }
  void set(pdt::CellId c, std::uint32_t incarnation) { slot(c).store(incarnation, std::memory_order_release); }
  std::uint32_t get(pdt::CellId c) { return slot(c).load(std::memory_order_acquire); }

 private:
  static constexpr std::size_t chunk_bits = 16, max_chunks = std::size_t{1} << 16;
  struct Chunk {
    std::atomic<std::uint32_t> v[std::size_t{1} << chunk_bits] = {};
  };
  std::atomic<std::uint32_t>& slot(pdt::CellId c) {
    std::atomic<Chunk*>& ptr = chunks_[c >> chunk_bits];
    Chunk* chunk = ptr.load(std::memory_order_acquire);
    if (!chunk) {
      auto* fresh = new Chunk();
      if (ptr.compare_exchange_strong(chunk, fresh, std::memory_order_acq_rel))
        chunk = fresh;
      else
        delete fresh;  // another thread got there first; `chunk` is its
    }
    return chunk->v[c & ((std::size_t{1} << chunk_bits) - 1)];
  }
  std::unique_ptr<std::atomic<Chunk*>[]> chunks_;
};

// The stream actually carried out, as an operation stream, into the caller's
// pdt::OpWriter (text, or binary for a .opsb name): each operation is written
// by the change hook, inside the operation (so the file's order is one in
// which conflicting operations happened), with insertions numbered in that
// order and removals naming them. The caller closes the writer (commits the
// file) once its other outputs are written too.
class Trace {
 public:
  explicit Trace(pdt::OpWriter* writer) : writer_(writer) {}
  void inserted(std::uint64_t incarnation, const Point3& p) {
    write([&] { index_of_[incarnation] = writer_->insert(p); });
  }
  // A duplicate insertion and its undo (the refiner never keeps one): both
  // written, so the stream stays the one carried out.
  std::uint64_t duplicate(const Point3& p) {
    std::uint64_t k = 0;
    write([&] { k = writer_->insert(p); });
    return k;
  }
  void removed_insertion(std::uint64_t k) {
    write([&] { writer_->remove(k); });
  }
  void removed(std::uint64_t incarnation) {
    write([&] {
      auto it = index_of_.find(incarnation);
      if (it == index_of_.end()) return;
      writer_->remove(it->second);
      index_of_.erase(it);
    });
  }

 private:
  // Under the lock, and once a write has failed (a full disk) every later
  // call throws that first error again: hooks on other threads would
  // otherwise report "closed", and the engine keeps whichever came first.
  template <class F>
  void write(F&& f) {
    if (writer_ == nullptr) return;
    std::lock_guard lock(m_);
    if (failed_) std::rethrow_exception(failed_);
    try {
      f();
    } catch (...) {
      failed_ = std::current_exception();
      throw;
    }
  }
  pdt::OpWriter* writer_;  // null: no trace asked for
  std::mutex m_;
  std::exception_ptr failed_;
  std::unordered_map<std::uint64_t, std::uint64_t> index_of_;  // live vertex incarnation -> its insertion
};

struct Bad {
  pdt::CellHandle cell;
  Point3 circumcentre;
  double radius = 0;
  bool too_big_or_skinny = false;  // else bad only for a missing surface sample
};

struct Detached {
  struct promise_type {
    Detached get_return_object() noexcept { return {}; }
    std::suspend_never initial_suspend() noexcept { return {}; }
    std::suspend_never final_suspend() noexcept { return {}; }
    void return_void() noexcept {}
    void unhandled_exception() { throw; }  // the engine catches it; drain() rethrows
  };
};

class Refiner {
 public:
  // lanes: how many boxes of the domain hold their own queue of bad cells
  // (Lane, below).
  Refiner(const RefineOptions& o, pdt::Engine& e, Trace& trace, unsigned lanes, std::vector<Point3> samples)
      : o_(o),
        e_(e),
        trace_(trace),
        samples_(std::move(samples), 0.5 * o.size),
        snap_(snap_radius(o.size)),
        protect_(protect_radius(o.size)),
        lanes_(std::max(1u, lanes)) {
    const pdt::Box& bx = o.domain.box;
    lo_ = {bx.lo.x, bx.lo.y, bx.lo.z};
    extent_ = {bx.hi.x - bx.lo.x, bx.hi.y - bx.lo.y, bx.hi.z - bx.lo.z};
    // Each prime factor of the lane count, largest first, cuts the axis whose
    // boxes are longest: the boxes come out about as wide as they are long.
    unsigned rest = static_cast<unsigned>(lanes_.size());
    std::vector<unsigned> factors;
    for (unsigned f = 2; rest > 1;) {
      if (rest % f == 0) {
        factors.push_back(f);
        rest /= f;
      } else {
        ++f;
      }
    }
    for (auto f = factors.rbegin(); f != factors.rend(); ++f) {
      int a = 0;
      for (int i = 1; i < 3; ++i)
        if (extent_[i] / cuts_[i] > extent_[a] / cuts_[a]) a = i;
      cuts_[a] *= *f;
    }
    for (double& x : extent_)
      if (!(x > 0)) x = 1;
    assert(static_cast<std::size_t>(cuts_[0]) * cuts_[1] * cuts_[2] == lanes_.size());
  }

  // Inside every operation that makes or deletes a vertex, on its worker.
  void on_change(const pdt::Changes& c) {
    for (const pdt::CellHandle& h : c.destroyed) cells_.set(h.id, 0);
    for (const pdt::CellView& v : c.created) {
      cells_.set(v.handle.id, v.handle.incarnation);
      if (!v.finite()) continue;
      const TetShape s = shape(v.points);
      if (!s.ok || !(o_.domain.f(s.circumcentre) < 0)) continue;
      if (s.circumradius > o_.size || s.radius_edge > o_.ratio) push({v.handle, s.circumcentre, s.circumradius, true});
    }
    if (c.kind == pdt::OpKind::remove) {
      trace_.removed(c.vertex.incarnation);
      return;
    }
    // An insertion: its point is in every cell it made (or, with no cell yet,
    // it is one of the first points).
    Point3 p{};
    bool found = false;
    for (const pdt::CellView& v : c.created)
      for (int i = 0; i < 4 && !found; ++i)
        if (v.vertices[i] == c.vertex.id) p = v.points[i], found = true;
    if (!found) p = corners_[std::max(0, corner_now_.load())];  // one of the first corners: no cell yet
    trace_.inserted(c.vertex.incarnation, p);
    if (!samples_.is_sample(p)) return;
    // A sample: the vertices (not samples) inside its protecting ball go. The
    // ids are live while the operation holds them; a removal submitted now
    // is pinned to the incarnation it sees.
    std::vector<pdt::VertexId> doomed;
    for (const pdt::CellView& v : c.created)
      for (int i = 0; i < 4; ++i) {
        const pdt::VertexId w = v.vertices[i];
        if (w == pdt::infinite_vertex || w == c.vertex.id) continue;
        if (dist2(v.points[i], p) < protect_ * protect_ && !samples_.is_sample(v.points[i]) &&
            std::find(doomed.begin(), doomed.end(), w) == doomed.end())
          doomed.push_back(w);
      }
    // Counted when carried out: a vertex may already be gone (another
    // sample's hook removed it first), and that removal then does nothing.
    for (pdt::VertexId w : doomed)
      e_.remove(w, [this](const pdt::OpResult& r) {
        if (!r.error && r.remove == pdt::RemoveResult::removed) removals_.fetch_add(1, std::memory_order_relaxed);
      });
  }

  // A refiner coroutine: cells from the lane it holds (Lane, below) until
  // every lane is empty.
  Detached work() {
    Bad b;
    Taker taker;
    while (!stop_.load(std::memory_order_relaxed) && pop(taker, b)) {
      const std::size_t from = taker.lane;  // the lane b came from
      if (cells_.get(b.cell.id) != b.cell.incarnation) {
        lanes_[from].dead.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      if (insertions_.load(std::memory_order_relaxed) >= o_.budget) {
        budget_hit_.store(true);
        stop_.store(true);
        break;
      }
      insertions_.fetch_add(1, std::memory_order_relaxed);
      // Within a sample's snap radius: never the circumcentre. The sample
      // instead if it is not in yet (then this cell is judged again), else
      // nothing: the cell lies in the protected layer along the surface.
      if (const std::int64_t near = samples_.nearest_within(b.circumcentre, snap_); near >= 0) {
        if (samples_.claim(static_cast<std::uint32_t>(near))) {
          samples_inserted_.fetch_add(1, std::memory_order_relaxed);
          co_await insert_once(samples_[static_cast<std::uint32_t>(near)]);
          push(b);
        } else {
          protected_.fetch_add(1, std::memory_order_relaxed);
          insertions_.fetch_sub(1, std::memory_order_relaxed);
        }
        continue;
      }
      // Only if the cell is still alive when the insertion runs: two cells
      // with (nearly) one circumsphere, judged at once, must not both put
      // their (nearly equal) circumcentres in.
      const pdt::InsertResult r = co_await e_.insert_if_alive(b.circumcentre, b.cell);
      if (r.vertex == pdt::no_vertex) {
        lanes_[from].died_queued.fetch_add(1, std::memory_order_relaxed);
        insertions_.fetch_sub(1, std::memory_order_relaxed);
      } else {
        circumcentres_.fetch_add(1, std::memory_order_relaxed);
        if (!r.inserted) undo_duplicate(r.vertex, b.circumcentre);
      }
    }
    if (taker.holds) lanes_[taker.lane].held.store(false, std::memory_order_release);  // stopped with cells left
  }

  // co_await insert_once(p): inserts p; if it was there already (two cells
  // with one circumcentre, judged at once), undoes the duplicate, so that no
  // vertex keeps a multiplicity.
  struct InsertOnce {
    Refiner* r;
    Point3 p;
    pdt::InsertAwaitable insertion;
    bool await_ready() { return false; }
    bool await_suspend(std::coroutine_handle<> h) { return insertion.await_suspend(h); }
    void await_resume() {
      const pdt::InsertResult res = insertion.await_resume();
      if (!res.inserted) r->undo_duplicate(res.vertex, p);
    }
  };
  InsertOnce insert_once(const Point3& p) { return InsertOnce{this, p, e_.insert(p)}; }
  Detached undo_duplicate(pdt::VertexId v, Point3 p) {
    const std::uint64_t k = trace_.duplicate(p);
    (void)co_await e_.remove(v);  // lowers the multiplicity back to 1: no change to report
    trace_.removed_insertion(k);
  }

  // The box's corners first, so that the triangulation covers the domain;
  // then a coarse lattice inside it (spacing 3 * size, jittered by the seed
  // against exactly cospherical cells), so that its cells have circumcentres
  // inside and refinement has somewhere to start.
  void start() {
    // Every sample goes in before the end: if they and the corners exceed
    // the budget, no run can finish within it.
    if (!within_budget(8 + samples_.size())) {
      samples_over_budget_.store(true);
      return;
    }
    const pdt::Box& b = o_.domain.box;
    for (int k = 0; k < 8; ++k) {
      if (!within_budget(1)) return;
      corners_[k] = {k & 1 ? b.hi.x : b.lo.x, k & 2 ? b.hi.y : b.lo.y, k & 4 ? b.hi.z : b.lo.z};
      insertions_.fetch_add(1);
      start_points_.fetch_add(1);
      corner_now_.store(k);
      e_.insert(corners_[k], {});
      e_.drain();  // one at a time: the hook knows which corner it sees
    }
    corner_now_.store(-1);
    const double h = 3 * o_.size;
    std::mt19937_64 rng(o_.seed ^ 0x5DEECE66Dull);
    std::uniform_real_distribution<double> jitter(-0.05 * h, 0.05 * h);
    std::vector<Point3> seeds;
    for (double z = b.lo.z + h / 2; z < b.hi.z; z += h)
      for (double y = b.lo.y + h / 2; y < b.hi.y; y += h)
        for (double x = b.lo.x + h / 2; x < b.hi.x; x += h) {
          const Point3 p{x + jitter(rng), y + jitter(rng), z + jitter(rng)};
          if (o_.domain.f(p) < -o_.size) seeds.push_back(p);  // well inside: clear of the surface
        }
    if (!within_budget(seeds.size())) return;
    insertions_.fetch_add(seeds.size());
    start_points_.fetch_add(seeds.size());
    e_.insert_batch(seeds);
    e_.drain();
  }
  // Whether n more points fit the budget; if not, the run stops here, saying
  // the budget was hit.
  bool within_budget(std::uint64_t n) {
    if (insertions_.load() + n <= o_.budget) return true;
    std::uint64_t none = 0;
    budget_step_.compare_exchange_strong(none, n);  // the first step refused
    budget_hit_.store(true);
    stop_.store(true);
    return false;
  }
  // The surface samples no refinement step has asked for yet: all at once.
  // Each one's insertion removes the vertices inside its protecting ball (the
  // hook), and the cells that makes are judged again.
  std::size_t insert_remaining_samples() {
    std::vector<Point3> rest;
    for (std::uint32_t i = 0; i < samples_.size(); ++i)
      if (samples_.claim(i)) rest.push_back(samples_[i]);
    if (rest.empty() || !within_budget(rest.size())) return 0;
    insertions_.fetch_add(rest.size());
    samples_inserted_.fetch_add(rest.size());
    e_.insert_batch(rest);
    return rest.size();
  }
  // Exact when nothing runs (after drain); a snapshot meanwhile.
  std::uint64_t queued() const {
    std::int64_t n = 0;
    for (const Lane& l : lanes_)
      n += static_cast<std::int64_t>(l.pushed.load(std::memory_order_relaxed)) -
           static_cast<std::int64_t>(l.popped.load(std::memory_order_relaxed));
    return static_cast<std::uint64_t>(std::max<std::int64_t>(n, 0));
  }
  bool stopped() const { return stop_.load(); }

  void fill(RefineStats& st) const {
    st.insertions = insertions_.load();
    st.samples = samples_inserted_.load();
    st.circumcentres = circumcentres_.load();
    st.removals = removals_.load();
    st.dead_skipped = 0;
    st.died_in_engine = 0;
    for (const Lane& l : lanes_) {
      st.dead_skipped += l.dead.load();
      st.died_in_engine += l.died_queued.load();
    }
    st.protected_skipped = protected_.load();
    st.budget_hit = budget_hit_.load();
    st.budget_step = budget_step_.load();
    st.surface_samples = samples_.size();
    st.start_points = start_points_.load();
    st.samples_over_budget = samples_over_budget_.load();
  }

 private:
  void push(const Bad& b) {
    Lane& to = lanes_[lane_of(b.circumcentre)];
    to.queue.push(b);  // counted once in (a push that throws counts nothing)
    to.pushed.fetch_add(1, std::memory_order_relaxed);
  }
  // The lane of the box holding p (cuts_ boxes of equal size along each
  // axis of the domain's box; a point off the box goes to the nearest box).
  std::size_t lane_of(const Point3& p) const {
    const double at[3] = {p.x, p.y, p.z};
    std::size_t lane = 0;
    for (int i = 2; i >= 0; --i) {
      const double k = std::floor((at[i] - lo_[i]) / extent_[i] * cuts_[i]);
      const unsigned c = !(k > 0) ? 0 : static_cast<unsigned>(std::min(k, static_cast<double>(cuts_[i] - 1)));  // NaN: 0
      lane = lane * cuts_[i] + c;
    }
    return lane;
  }
  // Which lane a coroutine takes cells from, and whether it holds it.
  struct Taker {
    std::size_t lane = 0;
    bool holds = false;
    unsigned shared_left = 0;  // not holding it: cells to take from `lane` before looking again
  };
  // The next cell for a coroutine: from its lane while that has cells; then
  // from the fullest lane nobody holds, which it holds from then on; if every
  // lane with cells is held, from the fullest of those, held by another, for
  // up to shared_take cells before it looks again (a look reads every lane).
  static constexpr unsigned shared_take = 32;
  bool pop(Taker& t, Bad& b) {
    if ((t.holds || lanes_.size() == 1) && take(t.lane, b)) return true;
    if (t.shared_left > 0) {
      --t.shared_left;
      if (take(t.lane, b)) return true;
      t.shared_left = 0;
    }
    if (t.holds) lanes_[t.lane].held.store(false, std::memory_order_release), t.holds = false;
    for (;;) {
      std::size_t best = lanes_.size(), shared = lanes_.size();
      std::int64_t most = 0, most_shared = 0;
      for (std::size_t i = 0; i < lanes_.size(); ++i) {
        const Lane& l = lanes_[i];
        const std::int64_t n = static_cast<std::int64_t>(l.pushed.load(std::memory_order_relaxed)) -
                               static_cast<std::int64_t>(l.popped.load(std::memory_order_relaxed));
        if (n <= 0) continue;
        if (!l.held.load(std::memory_order_relaxed)) {
          if (n > most) most = n, best = i;
        } else if (n > most_shared) {
          most_shared = n, shared = i;
        }
      }
      if (best < lanes_.size()) {
        if (lanes_[best].held.exchange(true, std::memory_order_acq_rel)) continue;  // another came first
        t = {best, true, 0};
        if (take(best, b)) return true;
        lanes_[best].held.store(false, std::memory_order_release), t.holds = false;
        // Emptied since it was counted (a count lags its queue while a cell
        // is being taken): look everywhere once, below, rather than again.
      } else if (shared < lanes_.size()) {
        t = {shared, false, shared_take - 1};
        if (take(shared, b)) return true;
      }
      // Nothing counted, or nothing where it was: any cell, from any lane. A
      // cell pushed after this look is taken by a coroutine still running,
      // or in the next round (refine() runs rounds until every lane is empty).
      for (std::size_t i = 0; i < lanes_.size(); ++i)
        if (take(i, b)) {
          t = {i, false, 0};
          return true;
        }
      return false;
    }
  }
  bool take(std::size_t lane, Bad& b) {
    if (!lanes_[lane].queue.try_pop(b)) return false;
    lanes_[lane].popped.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  const RefineOptions& o_;
  pdt::Engine& e_;
  Trace& trace_;
  Samples samples_;
  double snap_, protect_;
  CellTable cells_;
  // The bad cells, in lanes: the domain's box cut into boxes (cuts_ along
  // each axis), a FIFO queue per box; the hook queues a bad cell in the
  // lane of its circumcentre. A refiner coroutine holds one lane at a time
  // and takes its cells until it is empty, then holds the fullest lane that
  // nobody holds (pop; when every lane with cells is held, it takes a few
  // from the fullest of those); there are 8 lanes a coroutine, so that a lane is
  // free to take as a rule (a domain leaves many of its box's lanes empty).
  // So concurrent coroutines refine apart from
  // each other: neighbouring bad cells (queued together by one insertion)
  // taken by several coroutines at once make insertions that collide (a
  // lock held by another worker: a rollback) or find their cell destroyed by
  // a neighbour's insertion (dead), and the engine's workers serve different
  // blocks. Within a lane the FIFO keeps the order cells were made in, and
  // with it the locality the kernel's caches need. With one thread there is
  // one lane: nothing runs concurrently, and boxes would only cost locality.
  // (Lanes were first one per arena thread, a cell queued on the thread that
  // made it; on the torus at size 0.025 with 2 workers they gave 1.36 s
  // against 1.20 s for a lane per coroutine, alternating runs; a random pick
  // from the lane: 3.1 s, all locality lost. Slabs along the box's longest
  // axis, one per coroutine, each coroutine taking from its own first, then
  // from the next: on the torus, whose box the ring leaves empty at both
  // ends, 30% of the cells were taken from a neighbour's lane, beside its
  // coroutine: 0.74 rollbacks an insertion at 16 workers on 16 cores. On
  // the torus at size 0.018 with 2 workers on 2 cores, held lanes took the
  // rollbacks from 49-52k to 4.7-5.5k, the time from 2.13-3.21 s to
  // 1.89-2.00 s, and the peak from 256 to 227 MiB, alternating runs.)
  // Counters are per lane, written by whichever thread pushes or pops there.
  struct alignas(64) Lane {
    tbb::concurrent_queue<Bad> queue;
    std::atomic<bool> held{false};  // a coroutine takes its cells (pop)
    // dead: found dead when taken; died_queued: alive when submitted, dead
    // when its insertion ran (insert_if_alive did nothing)
    std::atomic<std::uint64_t> pushed{0}, popped{0}, dead{0}, died_queued{0};
  };
  std::vector<Lane> lanes_;
  // The domain's box (its lower corner and extents, an extent of 0 taken as
  // 1) and how many lanes' boxes it is cut into along each axis; the product
  // of the cuts is the number of lanes.
  std::array<double, 3> lo_{}, extent_{};
  std::array<unsigned, 3> cuts_{1, 1, 1};
  std::array<Point3, 8> corners_{};
  std::atomic<int> corner_now_{-1};  // the corner being inserted, while start() runs
  std::atomic<bool> stop_{false}, budget_hit_{false}, samples_over_budget_{false};
  std::atomic<std::uint64_t> budget_step_{0};  // RefineStats::budget_step
  std::atomic<std::uint64_t> insertions_{0}, samples_inserted_{0}, circumcentres_{0}, removals_{0},
      protected_{0}, start_points_{0};
};

}  // namespace

RefineStats refine(pdt::Triangulation& t, const RefineOptions& o) {
  auto bad = [](const std::string& what) { throw pdt::Error(pdt::ErrorCode::invalid_argument, what); };
  if (!(o.size > 0) || !std::isfinite(o.size)) bad("the size bound must be a positive number, not " + std::to_string(o.size));
  if (!(o.ratio >= min_ratio) || !std::isfinite(o.ratio))
    bad("the radius-edge bound must be at least " + std::to_string(min_ratio).substr(0, 3) +
        " (below it Delaunay refinement need not terminate), not " + std::to_string(o.ratio));
  if (o.workers == 0) bad("the refiner needs at least one worker");
  const double extent = std::max({o.domain.box.hi.x - o.domain.box.lo.x, o.domain.box.hi.y - o.domain.box.lo.y,
                                  o.domain.box.hi.z - o.domain.box.lo.z});
  // At most 10^4 sizes across the box (a size of exactly extent / 10^4 passes
  // however the division rounds).
  if (extent / o.size > 1e4 * (1 + 1e-12)) {
    char why[200];
    std::snprintf(why, sizeof why,
                  "the size bound %g is too small for the %s domain: at most 10^4 sizes fit across its box (%g "
                  "across), so the smallest size is %g",
                  o.size, o.domain.name.c_str(), extent, extent / 1e4);
    bad(why);
  }
  RefineStats st;
  st.workers = o.workers;
  const auto start = std::chrono::steady_clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
  const unsigned threads = std::min(o.workers, std::max(1u, std::thread::hardware_concurrency()));
  tbb::global_control parallelism(
      tbb::global_control::max_allowed_parallelism,
      std::max<std::size_t>(threads + 1, tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
  tbb::task_arena arena(static_cast<int>(threads), 0);
  Trace trace(o.trace);
  // The surface samples, unless they alone exceed the budget: each kept
  // sample stands for a few crossed cells (those whose projected centres
  // fall within spacing / 2 of it: about 1.5, never near 8), so past 8 per
  // budgeted point the sampling stops, and with it the run. (64 per point
  // let a surface of 4.8M samples run a minute and take 1 GB before its
  // refusal under a budget of 100k.)
  bool too_many = false;
  constexpr std::size_t per_point = 8;
  const std::size_t cap =
      o.budget >= SIZE_MAX / per_point - 1 ? SIZE_MAX : static_cast<std::size_t>(per_point * (o.budget + 1));
  // First coarser looks, from extent / 16 down by factors of 4 to 4 times
  // the spacing: a surface's samples grow as 1 / spacing^2, so one whose
  // samples at spacing s, times (s / size)^2, exceed twice the budget is
  // refused without sampling it finely (which took minutes and gigabytes for
  // a gyroid of 10^8 samples). Each look costs about 1/16 of the next; the
  // factor 2 leaves room for the estimate's error, and a coarse look that
  // misses thin features only underestimates.
  if (cap != SIZE_MAX && o.size * 4 <= extent) {  // (a coarser look than the domain sees nothing)
    double s = o.size * 4;
    while (s * 4 <= extent / 16) s *= 4;
    for (; s >= o.size * 4 && !too_many; s /= 4) {
      const std::vector<Point3> coarse = surface_samples(o.domain, s, o.seed, cap, &too_many);
      const double estimate = static_cast<double>(coarse.size()) * (s / o.size) * (s / o.size);
      if (estimate > 2.0 * (static_cast<double>(o.budget) + 1)) too_many = true;
    }
  }
  std::vector<Point3> samples;
  if (!too_many) samples = surface_samples(o.domain, o.size, o.seed, cap, &too_many);
  if (!too_many && samples.empty()) {
    char why[256];
    std::snprintf(why, sizeof why,
                  "the size bound %g leaves the %s domain without surface samples: the sampling lattice of that "
                  "spacing misses its surface (its box is %g across); give a smaller size (a quarter of the box "
                  "or less samples every domain)",
                  o.size, o.domain.name.c_str(), extent);
    bad(why);
  }
  if (too_many) {  // refused before anything ran: nothing written to the trace
    st.budget_hit = st.samples_over_budget = true;
    st.seconds = seconds();
    return st;
  }
  {
    pdt::EngineOptions eo = pdt::EngineOptions::from_environment();
    eo.workers = o.workers;
    pdt::Engine e(t, o.domain.box, eo, &arena);
    // Rounds: refiner coroutines until the queue is empty, then drain (the
    // operations still running may queue more cells), until nothing is left.
    // 8 lanes a coroutine when threads run concurrently (Refiner::Lane),
    // at most 4096 unless there are more coroutines (a look reads every
    // lane's counts, and each lane's queue is about 1.4 KB).
    const unsigned coroutines = 4 * o.workers;
    const unsigned lanes = threads > 1 ? std::max(coroutines, std::min(8 * coroutines, 4096u)) : 1;
    Refiner r(o, e, trace, lanes, std::move(samples));
    e.set_change_hook([&r](const pdt::Changes& c) { r.on_change(c); }, true);
    r.start();
    bool surface_done = false;
    while (!r.stopped()) {
      if (r.queued() == 0) {
        // Refined as far as the interior asked: now the rest of the surface.
        if (surface_done || r.insert_remaining_samples() == 0) break;
        surface_done = true;
        e.drain();
        continue;
      }
      arena.execute([&] {
        for (unsigned k = 0; k < coroutines; ++k) r.work();
      });
      // drain() blocks: report progress from here meanwhile.
      std::atomic<bool> drained{false};
      std::thread reporter;
      if (o.progress)
        reporter = std::thread([&] {
          while (!drained.load()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(250));
            if (!drained.load()) o.progress(t.number_of_vertices(), r.queued(), seconds());
          }
        });
      try {
        e.drain();
      } catch (...) {
        drained.store(true);
        if (reporter.joinable()) reporter.join();
        throw;
      }
      drained.store(true);
      if (reporter.joinable()) reporter.join();
    }
    r.fill(st);
    st.engine = e.stats();
  }
  st.seconds = seconds();
  return st;
}

MeshQuality measure(const pdt::Triangulation& t, const Domain& d, double size, double ratio, std::uint64_t seed,
                    unsigned threads) {
  const Samples samples(surface_samples(d, size, seed), 0.5 * size);
  const double snap = snap_radius(size);
  // One cell into a partial result. Counts, minima and maxima: the sum of
  // the parts is the same whichever way the cells are split.
  auto judge = [&](pdt::CellId c, MeshQuality& q) {
    if (!t.is_finite_cell(c)) return;
    std::array<Point3, 4> p;
    for (int i = 0; i < 4; ++i) p[i] = t.point(t.cell_vertex(c, i));
    const Point3 centroid{(p[0].x + p[1].x + p[2].x + p[3].x) / 4, (p[0].y + p[1].y + p[2].y + p[3].y) / 4,
                          (p[0].z + p[1].z + p[2].z + p[3].z) / 4};
    const double dihedral = min_dihedral_degrees(p);
    const bool inside = d.f(centroid) < 0;
    if (inside) {
      ++q.inside;
      q.min_dihedral = std::min(q.min_dihedral, dihedral);
      if (dihedral < MeshQuality::sliver_degrees) ++q.slivers;
    }
    const TetShape s = shape(p);
    if (!s.ok && inside) ++q.unplaced;
    if (!s.ok || !(d.f(s.circumcentre) < 0)) return;
    if (samples.nearest_within(s.circumcentre, snap) >= 0) {
      ++q.protected_layer;
      return;
    }
    ++q.judged;
    q.min_dihedral_judged = std::min(q.min_dihedral_judged, dihedral);
    if (dihedral < MeshQuality::sliver_degrees) ++q.slivers_judged;
    q.worst_ratio = std::max(q.worst_ratio, s.radius_edge);
    q.largest_radius = std::max(q.largest_radius, s.circumradius);
    if (s.circumradius > size || s.radius_edge > ratio) ++q.violations;
  };
  auto join = [](MeshQuality a, const MeshQuality& b) {
    a.inside += b.inside;
    a.judged += b.judged;
    a.protected_layer += b.protected_layer;
    a.unplaced += b.unplaced;
    a.violations += b.violations;
    a.worst_ratio = std::max(a.worst_ratio, b.worst_ratio);
    a.largest_radius = std::max(a.largest_radius, b.largest_radius);
    a.min_dihedral = std::min(a.min_dihedral, b.min_dihedral);
    a.min_dihedral_judged = std::min(a.min_dihedral_judged, b.min_dihedral_judged);
    a.slivers += b.slivers;
    a.slivers_judged += b.slivers_judged;
    return a;
  };
  const pdt::CellId cells = t.cell_id_bound();
  threads = std::min(threads, std::max(1u, std::thread::hardware_concurrency()));  // as refine()'s arena
  if (threads <= 1) {
    MeshQuality q;
    for (pdt::CellId c = 0; c < cells; ++c) judge(c, q);
    return q;
  }
  // The triangulation's const queries are safe from several threads while
  // nothing changes it.
  tbb::task_arena arena(static_cast<int>(threads));
  return arena.execute([&] {
    return tbb::parallel_reduce(
        tbb::blocked_range<pdt::CellId>(0, cells, 4096), MeshQuality{},
        [&](const tbb::blocked_range<pdt::CellId>& r, MeshQuality q) {
          for (pdt::CellId c = r.begin(); c < r.end(); ++c) judge(c, q);
          return q;
        },
        join);
  });
}

}  // namespace pdt_refine
