// SPDX-License-Identifier: MIT
// pdt_fuzz: the differential fuzzer. Random cases, each a stream of
// insertions (duplicates and degenerate points included) and removals, cut
// into segments run one after the other on the same triangulation: each
// segment sequentially or on a fresh Engine (random workers, blocks,
// stealing, recuts, escalation, contention settings, submission form), sometimes with
// clear() between segments and callbacks that throw. At the end the
// triangulation must validate and equal CGAL's of the points left, with their
// multiplicities. Seeded and reproducible: a failure prints its seed, then a
// minimal stream (delta debugging, each candidate replayed a few times, as
// interleavings vary; the smallest failing one so far when M runs out),
// written as an .ops file.
//
//   pdt_fuzz [--seed S] [--cases N] [--seconds T] [--minimise-seconds M] [--out DIR] [--verbose]
//
// Defaults: seed 1, as many cases as fit in T = 60 seconds, minimising a
// failure for at most M = 120 seconds. The cases' seeds are S, S + 1, ...
// (a run prints its range): runs meant to cover different cases need seeds
// further apart than their case counts (a 600 s run makes a few thousand). Exit status 0 if
// every case matched, 1 on a mismatch (the stream is in DIR), 2 on a
// usage error.
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <coroutine>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <random>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include "pdt/pdt.hpp"

namespace {

using pdt::Point3;

// ---------------------------------------------------------------------------
// A case: operations in segments
// ---------------------------------------------------------------------------
struct Op {
  bool insert = true;
  Point3 p;                 // insert
  std::size_t target = 0;   // remove: the index (among this case's insertions) undone
};

enum class Runner { sequential, engine_callbacks, engine_batch, engine_coroutines };

struct Segment {
  std::size_t end = 0;  // ops [previous end, end)
  Runner runner = Runner::sequential;
  bool clear_before = false;
  unsigned workers = 1, blocks = 0, escalate = 64, window = 32;
  bool stealing = true, rebalance = true, throwing_callbacks = false;
  double low = 0.7, high = 0.9;
};

struct Case {
  std::uint64_t seed = 0;
  std::string source;  // how the points were drawn
  std::vector<Op> ops;
  std::vector<Segment> segments;
};

const char* runner_name(Runner r) {
  switch (r) {
    case Runner::sequential: return "sequential";
    case Runner::engine_callbacks: return "engine (callbacks)";
    case Runner::engine_batch: return "engine (batches)";
    case Runner::engine_coroutines: return "engine (coroutines)";
  }
  return "?";
}

// Point sources: degenerate ones on purpose.
std::vector<Point3> draw_points(std::mt19937_64& rng, std::size_t n, std::string& source) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Point3> pts;
  switch (rng() % 8) {
    case 0:
      source = "uniform";
      for (std::size_t i = 0; i < n; ++i) pts.push_back({u(rng), u(rng), u(rng)});
      break;
    case 1: {
      source = "integer lattice";
      const int k = 2 + static_cast<int>(std::cbrt(static_cast<double>(n)));
      for (std::size_t i = 0; i < n; ++i)
        pts.push_back({double(rng() % k), double(rng() % k), double(rng() % k)});
      break;
    }
    case 2: {
      source = "exactly cospherical";
      const int r2 = 50 + static_cast<int>(rng() % 200);
      std::vector<Point3> all;
      const int r = static_cast<int>(std::sqrt(double(r2))) + 1;
      for (int x = -r; x <= r; ++x)
        for (int y = -r; y <= r; ++y)
          for (int z = -r; z <= r; ++z)
            if (x * x + y * y + z * z == r2) all.push_back({double(x), double(y), double(z)});
      if (all.empty()) all.push_back({0, 0, 0});
      for (std::size_t i = 0; i < n; ++i) pts.push_back(all[rng() % all.size()]);
      break;
    }
    case 3:
      source = "a coplanar layer, then a few points off it";
      for (std::size_t i = 0; i < n; ++i) pts.push_back({u(rng), u(rng), i % 17 == 16 ? u(rng) : 0.5});
      break;
    case 4:
      source = "collinear, then a plane, then space";
      for (std::size_t i = 0; i < n; ++i) {
        const double t = u(rng);
        pts.push_back(i < n / 3 ? Point3{t, 2 * t, 3 * t} : i < 2 * n / 3 ? Point3{t, u(rng), 0} : Point3{t, u(rng), u(rng)});
      }
      break;
    case 5:
      source = "clustered (a tiny box inside a big one)";
      for (std::size_t i = 0; i < n; ++i)
        pts.push_back(i % 5 ? Point3{0.5 + 1e-9 * u(rng), 0.5 + 1e-9 * u(rng), 0.5 + 1e-9 * u(rng)} : Point3{u(rng), u(rng), u(rng)});
      break;
    case 6:
      source = "huge coordinates";
      for (std::size_t i = 0; i < n; ++i) pts.push_back({1e300 * (u(rng) - 0.5), 1e300 * (u(rng) - 0.5), 1e300 * (u(rng) - 0.5)});
      break;
    default:
      source = "a 4x4x4 grid of exact duplicates";
      for (std::size_t i = 0; i < n; ++i) pts.push_back({double(rng() % 4), double(rng() % 4), double(rng() % 4)});
      break;
  }
  return pts;
}

Case make_case(std::uint64_t seed) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 1);
  Case c;
  c.seed = seed;
  const std::size_t n = 20 + rng() % (rng() % 4 == 0 ? 3000 : 400);
  std::vector<Point3> pts = draw_points(rng, n, c.source);
  // Insertions with duplicates (a point again) and interleaved removals of live insertions.
  std::vector<std::size_t> live;
  std::size_t inserted = 0;
  const double p_remove = std::uniform_real_distribution<double>(0, 0.45)(rng);
  for (std::size_t i = 0; i < pts.size();) {
    const double x = std::uniform_real_distribution<double>(0, 1)(rng);
    if (!live.empty() && x < p_remove) {
      const std::size_t k = rng() % live.size();
      c.ops.push_back({false, {}, live[k]});
      live[k] = live.back();
      live.pop_back();
    } else {
      const Point3 p = inserted > 0 && x < p_remove + 0.05 ? pts[rng() % i] : pts[i++];
      c.ops.push_back({true, p, 0});
      live.push_back(inserted++);
    }
  }
  // Segments.
  const std::size_t parts = 1 + rng() % 4;
  for (std::size_t k = 1; k <= parts; ++k) {
    Segment s;
    s.end = k == parts ? c.ops.size() : c.ops.size() * k / parts;
    s.runner = static_cast<Runner>(rng() % 4);
    s.clear_before = k > 1 && rng() % 8 == 0;
    const unsigned worker_counts[] = {1, 2, 3, 4, 8, 16};
    s.workers = worker_counts[rng() % 6];
    s.blocks = rng() % 3 == 0 ? static_cast<unsigned>(1 + rng() % 12) : 0;
    s.stealing = rng() % 4 != 0;
    s.rebalance = rng() % 4 != 0;
    s.escalate = rng() % 3 == 0 ? static_cast<unsigned>(1 + rng() % 8) : 64;
    s.window = 1 + static_cast<unsigned>(rng() % 32);
    s.low = std::uniform_real_distribution<double>(0, 0.9)(rng);
    s.high = std::uniform_real_distribution<double>(s.low, 1)(rng);
    s.throwing_callbacks = rng() % 6 == 0;
    c.segments.push_back(s);
  }
  return c;
}

// ---------------------------------------------------------------------------
// Running a case
// ---------------------------------------------------------------------------
struct Detached {
  struct promise_type {
    Detached get_return_object() noexcept { return {}; }
    std::suspend_never initial_suspend() noexcept { return {}; }
    std::suspend_never final_suspend() noexcept { return {}; }
    void return_void() noexcept {}
    void unhandled_exception() noexcept { std::terminate(); }
  };
};

// What the case's triangulation must hold: the points of live insertions.
struct Outcome {
  std::vector<Point3> expected;  // with repetitions
  std::string error;             // an operation that failed, or a refusal, if any
};

Detached co_insert(pdt::Engine& e, Point3 p, pdt::VertexHandle* out, std::atomic<int>& pending, std::string* err,
                   std::mutex& m) {
  try {
    *out = (co_await e.insert(p)).handle();
  } catch (const std::exception& x) {
    std::lock_guard lock(m);
    *err = x.what();
  }
  pending.fetch_sub(1);
}

Detached co_remove(pdt::Engine& e, pdt::VertexHandle h, std::atomic<int>& pending, std::string* err, std::mutex& m) {
  try {
    (void)co_await e.remove(h);
  } catch (const std::exception& x) {
    std::lock_guard lock(m);
    *err = x.what();
  }
  pending.fetch_sub(1);
}

bool check(const pdt::Triangulation& t, const std::vector<Point3>& expected, std::string& why);

// Runs c on a fresh triangulation; true if the result matches.
bool run_case(const Case& c, std::string& why, bool verbose) {
  pdt::Triangulation t;
  // Per insertion: its vertex handle (duplicates share a vertex, each is one
  // insertion of it: removal lowers the multiplicity) and its point.
  std::vector<pdt::VertexHandle> handle;
  std::vector<Point3> point;
  std::vector<bool> alive;
  std::size_t begin = 0;
  for (const Segment& s : c.segments) {
    if (verbose)
      std::printf("  ops [%zu, %zu): %s, %u workers, blocks %u, stealing %d, recuts %d, escalate %u%s%s\n", begin,
                  s.end, runner_name(s.runner), s.workers, s.blocks, s.stealing, s.rebalance, s.escalate,
                  s.clear_before ? ", clear first" : "",
                  s.throwing_callbacks ? ", callbacks throw" : "");
    if (s.clear_before) {
      t.clear();
      std::fill(alive.begin(), alive.end(), false);
    }
    // Insertions of this segment are numbered on from the case's count; a
    // removal whose insertion is dead (cleared) is skipped, as the stream was
    // written for the live set.
    std::vector<std::size_t> ins_index;  // op index -> insertion index
    for (std::size_t i = begin; i < s.end; ++i) {
      if (c.ops[i].insert) {
        ins_index.push_back(point.size());
        point.push_back(c.ops[i].p);
        handle.push_back({});
        alive.push_back(true);
      } else {
        ins_index.push_back(c.ops[i].target);
      }
    }
    try {
      if (s.runner == Runner::sequential) {
        for (std::size_t i = begin; i < s.end; ++i) {
          const std::size_t k = ins_index[i - begin];
          if (c.ops[i].insert) {
            handle[k] = t.insert(point[k]).handle();
          } else if (k < alive.size() && alive[k]) {
            t.remove(handle[k].id);  // by id: a duplicate's insertions share it
            alive[k] = false;
          }
        }
      } else {
        tbb::task_arena arena(2);
        std::mutex m;
        std::string op_error;
        arena.execute([&] {
          pdt::EngineOptions o;
          o.workers = s.workers;
          o.blocks_per_axis = s.blocks;
          o.stealing = s.stealing;
          o.rebalance = s.rebalance;
          o.escalate_after = s.escalate;
          o.contention_window = s.window;
          o.contention_low = s.low;
          o.contention_high = s.high;
          pdt::Box box{{-1e300, -1e300, -1e300}, {1e300, 1e300, 1e300}};
          pdt::Engine e(t, box, o);
          auto note = [&](const pdt::OpResult& r) {
            if (r.error) {
              std::lock_guard lock(m);
              try {
                std::rethrow_exception(r.error);
              } catch (const std::exception& x) {
                op_error = x.what();
              }
            }
          };
          std::atomic<int> pending{0};
          std::size_t i = begin;
          while (i < s.end) {
            // A run of insertions, then the removals that follow it: the
            // removals need the insertions' vertices, so the run is drained first.
            std::size_t j = i;
            while (j < s.end && c.ops[j].insert) ++j;
            if (s.runner == Runner::engine_batch && j > i) {
              std::vector<Point3> batch;
              for (std::size_t q = i; q < j; ++q) batch.push_back(point[ins_index[q - begin]]);
              const pdt::Engine::Ticket first = e.insert_batch(batch, note);
              e.drain();
              for (std::size_t q = i; q < j; ++q) handle[ins_index[q - begin]] = e.insertion_result(first + (q - i)).handle();
            } else {
              for (std::size_t q = i; q < j; ++q) {
                const std::size_t k = ins_index[q - begin];
                if (s.runner == Runner::engine_coroutines) {
                  pending.fetch_add(1);
                  co_insert(e, point[k], &handle[k], pending, &op_error, m);
                } else {
                  e.insert(point[k], [&, k](const pdt::OpResult& r) {
                    note(r);
                    handle[k] = r.insert.handle();
                    if (s.throwing_callbacks && k % 3 == 0) throw std::runtime_error("a client callback throws");
                  });
                }
              }
              try {
                e.drain();
              } catch (const std::runtime_error&) {
                // the throwing callbacks: expected, the engine goes on
              }
            }
            // Removals until the next insertion (by vertex id: duplicates share one).
            std::size_t r = j;
            while (r < s.end && !c.ops[r].insert) {
              const std::size_t k = ins_index[r - begin];
              if (k < alive.size() && alive[k]) {
                alive[k] = false;
                if (s.runner == Runner::engine_coroutines) {
                  pending.fetch_add(1);
                  co_remove(e, {handle[k].id, 0}, pending, &op_error, m);
                } else {
                  e.remove(handle[k].id, note);
                }
              }
              ++r;
            }
            e.drain();
            i = r;
          }
          e.drain();
          if (pending.load() != 0) op_error = "coroutines still pending after drain()";
        });
        if (!op_error.empty()) {
          why = "an operation failed on the engine: " + op_error;
          return false;
        }
      }
    } catch (const std::exception& x) {
      why = std::string("an operation threw: ") + x.what();
      return false;
    }
    begin = s.end;
  }
  std::vector<Point3> expected;
  for (std::size_t k = 0; k < point.size(); ++k)
    if (alive[k]) expected.push_back(point[k]);
  return check(t, expected, why);
}

// ---------------------------------------------------------------------------
// The reference: CGAL on the points left
// ---------------------------------------------------------------------------
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb, CGAL::Delaunay_triangulation_cell_base_3<K>>;
using CgalDT = CGAL::Delaunay_triangulation_3<K, Tds>;

struct PointHash {
  std::size_t operator()(const Point3& p) const {
    std::size_t h = std::hash<double>()(p.x + 0.0);
    h ^= std::hash<double>()(p.y + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
    return h ^ (std::hash<double>()(p.z + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2));
  }
};

bool check(const pdt::Triangulation& t, const std::vector<Point3>& expected, std::string& why) {
  if (!t.validate(&why)) {
    why = "validate() failed: " + why;
    return false;
  }
  std::unordered_map<Point3, std::uint32_t, PointHash> index, count;
  std::vector<std::pair<K::Point_3, std::uint32_t>> unique;
  for (const Point3& p : expected) {
    if (index.emplace(p, static_cast<std::uint32_t>(unique.size())).second)
      unique.emplace_back(K::Point_3(p.x, p.y, p.z), static_cast<std::uint32_t>(unique.size()));
    ++count[p];
  }
  if (t.number_of_vertices() != unique.size()) {
    why = std::to_string(t.number_of_vertices()) + " vertices, expected " + std::to_string(unique.size());
    return false;
  }
  for (pdt::VertexId v : t.vertices()) {
    auto it = count.find(t.point(v));
    if (it == count.end() || it->second != t.multiplicity(v)) {
      why = "vertex " + std::to_string(v) + " has the wrong multiplicity, or should not be there";
      return false;
    }
  }
  CgalDT dt(unique.begin(), unique.end());
  if (dt.dimension() != t.dimension()) {
    why = "dimension " + std::to_string(t.dimension()) + ", CGAL's " + std::to_string(dt.dimension());
    return false;
  }
  if (dt.dimension() < 3) return true;
  std::vector<std::array<std::uint32_t, 4>> mine, theirs;
  for (const auto& c : t.finite_cells()) {
    std::array<std::uint32_t, 4> a{};
    for (int i = 0; i < 4; ++i) a[i] = index.at(t.point(c[i]));
    std::sort(a.begin(), a.end());
    mine.push_back(a);
  }
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    std::array<std::uint32_t, 4> a{c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()};
    std::sort(a.begin(), a.end());
    theirs.push_back(a);
  }
  std::sort(mine.begin(), mine.end());
  std::sort(theirs.begin(), theirs.end());
  if (mine != theirs) {
    why = "the tetrahedra differ from CGAL's (" + std::to_string(mine.size()) + " vs " + std::to_string(theirs.size()) + ")";
    return false;
  }
  return true;
}

// ---------------------------------------------------------------------------
// Minimising a failure (delta debugging over the operations)
// ---------------------------------------------------------------------------
// c without the operations in [from, to): removals of dropped insertions go
// too, and later targets are renumbered.
Case without(const Case& c, std::size_t from, std::size_t to) {
  Case d = c;
  d.ops.clear();
  std::vector<std::size_t> new_index;  // old insertion index -> new, or npos
  const std::size_t gone = static_cast<std::size_t>(-1);
  std::vector<std::size_t> seg_end;
  std::size_t kept = 0, seg = 0;
  for (std::size_t i = 0; i < c.ops.size(); ++i) {
    while (seg < c.segments.size() && i == c.segments[seg].end) seg_end.push_back(kept), ++seg;
    const Op& op = c.ops[i];
    const bool drop = i >= from && i < to;
    if (op.insert) {
      new_index.push_back(drop ? gone : std::count_if(d.ops.begin(), d.ops.end(), [](const Op& o) { return o.insert; }));
      if (!drop) d.ops.push_back(op), ++kept;
    } else if (!drop && op.target < new_index.size() && new_index[op.target] != gone) {
      d.ops.push_back({false, {}, new_index[op.target]});
      ++kept;
    }
  }
  while (seg_end.size() < c.segments.size()) seg_end.push_back(kept);
  for (std::size_t s = 0; s < d.segments.size(); ++s) d.segments[s].end = seg_end[s];
  return d;
}

bool fails(const Case& c) {
  std::string why;
  for (int k = 0; k < 3; ++k)
    if (!run_case(c, why, false)) return true;
  return false;
}

// Delta debugging, for at most `budget` seconds (a failure that depends on
// the interleaving rarely repeats, and each candidate is replayed 3 times):
// *finished is false if the budget ran out first.
Case minimise(Case c, double budget, bool* finished) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(budget);
  *finished = true;
  for (std::size_t chunk = c.ops.size() / 2; chunk >= 1; chunk /= 2) {
    bool progress = true;
    while (progress) {
      progress = false;
      for (std::size_t from = 0; from < c.ops.size(); from += chunk) {
        if (std::chrono::steady_clock::now() >= until) {
          *finished = false;
          return c;
        }
        Case d = without(c, from, std::min(c.ops.size(), from + chunk));
        if (d.ops.size() < c.ops.size() && fails(d)) {
          c = d;
          progress = true;
          break;
        }
      }
    }
    if (chunk == 1) break;
  }
  return c;
}

void write_ops(const Case& c, const std::string& path) {
  pdt::OpStream s;
  for (const Op& op : c.ops) {
    pdt::Operation o;
    o.kind = op.insert ? pdt::Operation::Kind::insert : pdt::Operation::Kind::remove;
    o.point = op.p;
    o.target = op.target;
    s.ops.push_back(o);
  }
  pdt::write_ops(path, s);
}

}  // namespace

int main(int argc, char** argv) {
  std::uint64_t seed = 1, cases = 0;
  double seconds = 60, minimise_seconds = 120;
  std::string out = ".";
  bool verbose = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "pdt_fuzz: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--seed") seed = std::stoull(value());
      else if (a == "--cases") cases = std::stoull(value());
      else if (a == "--seconds") seconds = std::stod(value());
      else if (a == "--minimise-seconds") minimise_seconds = std::stod(value());
      else if (a == "--out") out = value();
      else if (a == "--verbose") verbose = true;
      else {
        std::fprintf(stderr, "usage: pdt_fuzz [--seed S] [--cases N] [--seconds T] [--minimise-seconds M] [--out DIR] [--verbose]\n");
        return 2;
      }
    } catch (const std::exception&) {
      std::fprintf(stderr, "pdt_fuzz: bad value for %s\n", a.c_str());
      return 2;
    }
  }
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
  std::uint64_t done = 0, ops = 0;
  for (std::uint64_t s = seed;; ++s) {
    if (cases ? done >= cases : elapsed() >= seconds) break;
    const Case c = make_case(s);
    if (verbose) std::printf("case %llu: %zu operations, %s\n", static_cast<unsigned long long>(s), c.ops.size(), c.source.c_str());
    std::string why;
    if (!run_case(c, why, verbose)) {
      std::printf("pdt_fuzz: MISMATCH in case %llu (%s, %zu operations): %s\n", static_cast<unsigned long long>(s),
                  c.source.c_str(), c.ops.size(), why.c_str());
      std::printf("pdt_fuzz: reproduce with: pdt_fuzz --seed %llu --cases 1 --verbose\n", static_cast<unsigned long long>(s));
      std::fflush(stdout);
      bool finished = true;
      const Case m = minimise(c, minimise_seconds, &finished);
      const std::string path = out + "/fuzz-failure-" + std::to_string(s) + ".ops";
      try {
        write_ops(m, path);
        if (!finished) std::printf("pdt_fuzz: minimising stopped after %g s (--minimise-seconds)\n", minimise_seconds);
        std::printf("pdt_fuzz: %s stream (%zu operations, segments as in the case) written to %s\n",
                    finished ? "minimal" : "smallest failing", m.ops.size(), path.c_str());
      } catch (const std::exception& x) {
        std::printf("pdt_fuzz: could not write the minimal stream: %s\n", x.what());
      }
      std::string again;
      if (run_case(m, again, true))
        again = "passed when run again: the failure depends on the interleaving, run it repeatedly";
      std::printf("pdt_fuzz: that stream, run once more: %s\n", again.c_str());
      return 1;
    }
    ++done;
    ops += c.ops.size();
  }
  std::printf("pdt_fuzz: %llu cases (seeds %llu..%llu, %llu operations) in %.1f s: every one equal to CGAL\n",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(seed),
              static_cast<unsigned long long>(seed + done - (done ? 1 : 0)), static_cast<unsigned long long>(ops), elapsed());
  return 0;
}
