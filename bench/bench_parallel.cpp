// SPDX-License-Identifier: MIT
// bench_parallel: the paper's §4.1 tables (Tables 2-4, and Table 1 of §3.3)
// for pdt::Engine, against CGAL's sequential and CGAL's own parallel
// Delaunay_triangulation_3, same points, same run.
//
//   bench_parallel [--points N] [--threads 1,2,4,8,16] [--dists uniform,normal,line]
//                  [--remove-fraction F] [--extreme] [--interleaved] [--skip-cgal-parallel] [--skip-main]
//                  [--skewed [--trace FILE]] [--seed S] [--csv FILE] [--timeout S]
//
// Per distribution: N points from pdt::generate (random order).
//  pdt      for each thread count T (1 always included: it is Speedup1's base):
//           a tbb::task_arena(T); inside it an Engine with options.threads = T.
//           Insertion phase: submit every insertion (insert(p, cb)), drain().
//           Removal phase: remove_insertion(ticket, cb) of the first F*N
//           tickets, drain(). cb only counts failed operations (its cost is
//           within the noise: one indirect call per operation, no allocation).
//           Each phase is timed separately; its engine statistics are the
//           difference of stats() before and after it.
//  pdt batch the same engine on CGAL parallel's terms: insert_batch(all)
//           (spatially sorted inside, timed), drain(); remove_insertions(the
//           first F*N) (sorted the same way), drain().
//  CGAL seq Delaunay_triangulation_3<Epick, Default, Fast_location>: insert(p)
//           one at a time in the same order (no spatial sort), then remove(vh)
//           of the first F*N one at a time (as bench_sequential).
//  CGAL par Delaunay_triangulation_3 over a Parallel_tag TDS with a
//           Spatial_lock_grid_3<Tag_priority_blocking> (50 cells per axis over
//           the domain), in a tbb::task_arena(T): insert(first, last) as one
//           batch (CGAL spatially sorts the batch first, inside the timing),
//           then remove(first, beyond) of the same first F*N vertices as a batch.
// Every configuration runs in a process of its own (fork; bench/common/child.hpp),
// started from the parent, which only generates the points and prints: in one
// process a configuration found pages the ones before it had faulted in and
// freed (1M normal points, pdt's batch with 2 workers: 1.36x its 1-worker
// speed there, 2.0x alone). Its peak resident memory is its own too (the
// "peak MiB" rows). Every final triangulation must have the same numbers of
// finite cells and vertices as CGAL's sequential one, and no pdt operation may
// fail (the timed loops pass a callback that only counts OpResult errors):
// MISMATCH is printed and the exit status is 1 otherwise.
//
// --extreme     §3.3 / Table 1: 3,000 normal points, insert all then remove
//               all, pdt with 1 and max(T) threads (median of 5 runs; CGAL
//               sequential for reference).
// --skewed      load balance: corner, kuzmin and front_x/y/z streams (removals
//               interleaved, fraction 0.3) and --trace FILE (a refiner's
//               trace), each replayed as one mixed phase with stealing and
//               recuts (the default), stealing only, and neither, against
//               CGAL sequential's replay.
// --interleaved a refiner-like stream: pdt::generate with
//               RemovalOrder::interleaved and remove fraction 0.3, replayed
//               as one mixed phase (pdt at each T, CGAL sequential replay).
// Order: the main tables, then --interleaved, then --extreme. A configuration
// running past --timeout (an engine livelock) prints HANG and exits 3; what
// was printed and written to the CSV before stays.
#include <sys/resource.h>

#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/version.h>
#include <CGAL/version.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/bench_util.hpp"
#include "common/cgal_runners.hpp"
#include "common/child.hpp"
#include "common/report.hpp"
#include "common/watchdog.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/ops.hpp"
#include "pdt/triangulation.hpp"
#include "support/sys_info.hpp"

namespace {

using namespace pdt_bench;
using pdt::support::Stopwatch;

constexpr std::uint64_t extreme_points = 3000;
constexpr int extreme_repeats = 5;
constexpr double interleaved_fraction = 0.3;

// ---- options ------------------------------------------------------------------
struct Options {
  std::uint64_t points = 2000000;
  std::vector<unsigned> threads{1, 2, 4, 8, 16};
  std::vector<std::string> dists{"uniform", "normal", "line"};
  double remove_fraction = 0.1;
  bool extreme = false;
  bool interleaved = false;
  bool skewed = false;
  std::string trace;  // a refiner's trace (pdt refine --trace), replayed with the skewed streams
  bool cgal_parallel = true;
  bool main_tables = true;  // false: the distributions only feed --interleaved
  std::uint64_t seed = 1;
  std::string csv;
  double timeout = 3600;  // seconds one configuration may take before the run is declared hung; 0 = never
};

Options parse(int argc, char** argv) {
  Options o;
  bool skip_cgal_parallel = false;
  ArgParser args(argv[0], "The paper's Tables 1-4 for pdt::Engine, against CGAL sequential and CGAL parallel");
  args.count("--points", "points per distribution (default 2000000)", o.points, 1);
  args.counts("--threads", "comma-separated thread counts (default 1,2,4,8,16; 1 is always run)", o.threads, 1, 4096);
  args.list("--dists", "comma-separated distributions (default uniform,normal,line; none: no main table)", o.dists);
  args.real("--remove-fraction", "fraction of the insertions undone after all of them, first inserted first "
            "(default 0.1)", o.remove_fraction, 0, 1);
  args.flag("--extreme", "also §3.3 (Table 1): 3,000 normal points, insert then remove all, 1 and max threads",
            o.extreme);
  args.flag("--interleaved", "also a refiner-like stream (RemovalOrder::interleaved, fraction 0.3)", o.interleaved);
  args.flag("--skewed", "also the load-balance table (issue 11): corner, kuzmin, front_x/y/z streams with removals "
            "interleaved (fraction 0.3); stealing + recuts, stealing only, neither", o.skewed);
  args.text("--trace", "with --skewed: also replay this operation stream (e.g. pdt refine --trace)", o.trace);
  args.flag("--skip-cgal-parallel", "do not run CGAL's Parallel_tag triangulation", skip_cgal_parallel);
  bool skip_main = false;
  args.flag("--skip-main", "no insert-then-remove table: the distributions feed --interleaved only", skip_main);
  args.count("--seed", "generator seed (default 1)", o.seed);
  args.text("--csv", "also write every measurement as a CSV row to this file", o.csv);
  args.real("--timeout", "declare a configuration hung after S seconds (default 3600; 0 = never; an extreme-case "
            "run: at most 120): print HANG and exit 3", o.timeout, 0, 1e300);
  args.parse(argc, argv);
  o.cgal_parallel = !skip_cgal_parallel;
  o.main_tables = !skip_main;
  // Speedup1 needs the 1-thread run; keep the order given otherwise, no repeats.
  std::vector<unsigned> ts{1};
  for (unsigned t : o.threads)
    if (std::find(ts.begin(), ts.end(), t) == ts.end()) ts.push_back(t);
  o.threads = ts;
  return o;
}

double config_timeout = 0;
std::size_t tbb_parallelism = 0;  // set by main: what each configuration's process allows oneTBB
double largest_peak_kib = 0;      // the largest configuration process's peak resident memory
constexpr double extreme_run_timeout = 120;

// ---- measurements ---------------------------------------------------------------
struct Phase {
  bool ran = false;
  double seconds = 0;
  std::uint64_t ops = 0;        // operations of the phase (submitted)
  double max_rb_pct = 0;        // max over workers of rollbacks / completed in this phase, in %
  std::uint64_t rollbacks = 0;  // summed over workers
  std::uint64_t sleeps = 0;
  double seconds_asleep = 0;
  double seconds_idle = 0;  // summed over workers: suspended with nothing to claim
  std::uint64_t deferred = 0;
  std::uint64_t global_ops = 0;
  unsigned busy_workers = 0;  // workers that completed at least one operation
  std::uint64_t errors = 0;   // operations whose OpResult carried an error
  std::uint64_t steals = 0;   // blocks served away from their home worker
  std::uint64_t recuts = 0;   // times the engine re-cut its blocks to where the work is
  double imbalance = 1;       // max / mean operations completed per worker in this phase
  // The configuration's process over the phase, every thread (getrusage):
  // CPU seconds in user and system mode, and minor page faults (first touches
  // of fresh pages, mostly). user + sys against seconds * threads tells busy
  // workers from idle or descheduled ones; sys, the kernel's part.
  double cpu_user = 0, cpu_sys = 0;
  std::uint64_t minor_faults = 0;
};

// What getrusage says of this process now (see Phase::cpu_user).
struct CpuUse {
  double user = 0, sys = 0;
  std::uint64_t minor_faults = 0;
};
CpuUse cpu_use_now() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  auto sec = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
  return {sec(u.ru_utime), sec(u.ru_stime), static_cast<std::uint64_t>(u.ru_minflt)};
}
void set_cpu_use(Phase& p, const CpuUse& a, const CpuUse& b) {
  p.cpu_user = b.user - a.user;
  p.cpu_sys = b.sys - a.sys;
  p.minor_faults = b.minor_faults - a.minor_faults;
}
// (user + sys) / (seconds * threads) in %: 100 when every thread ran all along.
std::string fmt_busy(const Phase& p, unsigned threads) {
  return p.seconds > 0 && threads ? fmt("%.0f", 100 * (p.cpu_user + p.cpu_sys) / (p.seconds * threads)) : "-";
}
// The workers' idle seconds over seconds * threads, in %.
std::string fmt_idle(const Phase& p, unsigned threads) {
  return p.seconds > 0 && threads ? fmt("%.1f", 100 * p.seconds_idle / (p.seconds * threads)) : "-";
}
// sys / (user + sys) in %.
std::string fmt_sys(const Phase& p) {
  return p.cpu_user + p.cpu_sys > 0 ? fmt("%.1f", 100 * p.cpu_sys / (p.cpu_user + p.cpu_sys)) : "-";
}

// Counts the operations that fail (OpResult::error): the only callback the
// timed loops pass. It fits std::function's small buffer (no allocation) and
// costs one indirect call per operation.
struct ErrorSink {
  std::atomic<std::uint64_t> count{0};
  std::mutex m;
  std::string first;
  void note(const pdt::OpResult& r) {
    if (!r.error) return;
    count.fetch_add(1, std::memory_order_relaxed);
    std::lock_guard<std::mutex> lock(m);
    if (!first.empty()) return;
    try {
      std::rethrow_exception(r.error);
    } catch (const std::exception& e) {
      first = e.what();
    } catch (...) {
      first = "unknown exception";
    }
  }
  pdt::Engine::Callback callback() {
    return [this](const pdt::OpResult& r) {
      if (r.error) note(r);
    };
  }
};

Phase phase_between(const pdt::EngineStats& a, const pdt::EngineStats& b, double seconds, std::uint64_t ops) {
  Phase p;
  p.ran = true;
  p.seconds = seconds;
  p.ops = ops;
  for (std::size_t i = 0; i < b.workers.size(); ++i) {
    const pdt::WorkerStats& w1 = b.workers[i];
    const pdt::WorkerStats w0 = i < a.workers.size() ? a.workers[i] : pdt::WorkerStats{};
    const std::uint64_t completed = w1.completed - w0.completed;
    const std::uint64_t rollbacks = w1.rollbacks - w0.rollbacks;
    // As the engine's own max_rollbacks_per_completed: 0 for a worker that completed nothing.
    if (completed) p.max_rb_pct = std::max(p.max_rb_pct, 100.0 * double(rollbacks) / double(completed));
    p.busy_workers += completed > 0;
    p.rollbacks += rollbacks;
    p.sleeps += w1.sleeps - w0.sleeps;
    p.seconds_asleep += w1.seconds_asleep - w0.seconds_asleep;
    p.seconds_idle += w1.seconds_idle - w0.seconds_idle;
    p.deferred += w1.deferred - w0.deferred;
  }
  p.global_ops = b.global_operations - a.global_operations;
  p.recuts = b.recuts - a.recuts;
  double sum = 0, most = 0;
  for (std::size_t i = 0; i < b.workers.size(); ++i) {
    const pdt::WorkerStats w0 = i < a.workers.size() ? a.workers[i] : pdt::WorkerStats{};
    const double completed = double(b.workers[i].completed - w0.completed);
    sum += completed;
    most = std::max(most, completed);
    p.steals += b.workers[i].steals - w0.steals;
  }
  p.imbalance = sum > 0 ? most / (sum / double(b.workers.size())) : 1;
  return p;
}

// What a configuration measured: plain data, so that it crosses the pipe from
// the configuration's process as bytes (isolated).
struct Measured {
  unsigned threads = 1;
  unsigned blocks = 0;  // pdt: blocks per axis
  Phase ins, rem, mixed;
  double bytes_per_tet = 0;  // pdt: memory_bytes() / number_of_cells() after the insertions
  Shape shape;
};

struct Result : Measured {
  std::string impl;         // pdt, cgal_seq, cgal_par
  std::string first_error;  // pdt: the first failed operation's message
  double peak_mib = 0;      // the configuration's process: peak resident memory
};

// A Result as plain bytes, to cross the pipe from a configuration's process.
struct WireResult {
  Measured measured;
  char impl[32] = {};
  char first_error[256] = {};
};

// Runs fn() -> Result in a process of its own, under a watchdog of `timeout`
// seconds (0: none) started there: past it the process prints HANG and exits
// 3, and so does this one. The parent starts no thread (no oneTBB, no
// watchdog): fork copies only the calling thread.
template <class Fn>
Result isolated(const std::string& what, double timeout, Fn fn) {
  WireResult w;
  const ChildStatus st = in_child(
      [&] {
        tbb::global_control gc(tbb::global_control::max_allowed_parallelism, tbb_parallelism);
        Watchdog dog;
        WatchdogGuard guard(&dog, what, timeout);
        const Result r = fn();
        WireResult out;
        out.measured = r;
        std::snprintf(out.impl, sizeof out.impl, "%s", r.impl.c_str());
        std::snprintf(out.first_error, sizeof out.first_error, "%s", r.first_error.c_str());
        return out;
      },
      w);
  if (st.exit_code == 3) std::exit(3);  // the child's watchdog printed HANG
  if (!st.ok) throw pdt::Error(pdt::ErrorCode::io_failure, what + ": " + st.error);
  Result r;
  static_cast<Measured&>(r) = w.measured;
  r.impl = w.impl;
  r.first_error = w.first_error;
  r.peak_mib = double(st.peak_kib) / 1024.0;
  largest_peak_kib = std::max(largest_peak_kib, double(st.peak_kib));
  return r;
}

// How the engine balances its load (issue 11): stealing and recuts (the
// default), stealing only, or the paper's static partition.
enum class Balance { recut, steal, none };

// Runs body(t, engine, errors, r) on a fresh triangulation with an Engine of
// `threads` workers in a tbb::task_arena(threads), then records the blocks,
// the first failed operation and the final shape in r.
template <class Body>
Result with_engine(const char* impl, const pdt::Box& box, unsigned threads, Body&& body,
                   Balance balance = Balance::recut) {
  Result r;
  r.impl = impl;
  r.threads = threads;
  {
    pdt::Triangulation t;
    tbb::task_arena arena(static_cast<int>(threads));
    arena.execute([&] {
      ErrorSink errors;  // outlives the engine, whose callbacks use it
      pdt::EngineOptions opts = pdt::EngineOptions::from_environment();
      opts.workers = threads;
      if (balance != Balance::recut) opts.rebalance = false;
      if (balance == Balance::none) opts.stealing = false;
      pdt::Engine e(t, box, opts);
      r.blocks = e.blocks_per_axis();
      body(t, e, errors, r);
      r.first_error = errors.first;
    });
    r.shape.finite_cells = t.number_of_finite_cells();
    r.shape.vertices = t.number_of_vertices();
  }
  return r;
}

// pdt: insertions then removals of the first n_remove insertions. One
// operation at a time (insert(p, cb), then remove_insertion(ticket, cb)), or
// in batch mode, on CGAL parallel's terms: insert_batch(all), then
// remove_insertions(the first n_remove), both spatially sorted inside.
Result run_pdt(const std::vector<pdt::Point3>& pts, const pdt::Box& box, std::size_t n_remove, unsigned threads,
               bool batch) {
  return with_engine(batch ? "pdt_batch" : "pdt", box, threads,
                     [&](pdt::Triangulation& t, pdt::Engine& e, ErrorSink& errors, Result& r) {
    std::vector<pdt::Engine::Ticket> tickets(n_remove);
    const pdt::EngineStats s0 = e.stats();
    const CpuUse c0 = cpu_use_now();
    Stopwatch sw;
    if (batch) {
      const pdt::Engine::Ticket first = e.insert_batch(pts, errors.callback());
      for (std::size_t k = 0; k < n_remove; ++k) tickets[k] = first + k;
    } else {
      for (std::size_t k = 0; k < pts.size(); ++k) {
        pdt::Engine::Ticket tk = e.insert(pts[k], errors.callback());
        if (k < n_remove) tickets[k] = tk;
      }
    }
    e.drain();
    const double t_ins = sw.seconds();
    const CpuUse c1 = cpu_use_now();
    const pdt::EngineStats s1 = e.stats();
    r.ins = phase_between(s0, s1, t_ins, pts.size());
    set_cpu_use(r.ins, c0, c1);
    r.ins.errors = errors.count.load();
    r.shape.cells_after_insert = t.number_of_finite_cells();
    r.bytes_per_tet = t.number_of_cells() ? double(t.memory_bytes()) / double(t.number_of_cells()) : 0;

    const CpuUse c2 = cpu_use_now();
    sw.restart();
    if (batch)
      e.remove_insertions(tickets, errors.callback());
    else
      for (std::size_t k = 0; k < n_remove; ++k) e.remove_insertion(tickets[k], errors.callback());
    e.drain();
    const double t_rem = sw.seconds();
    const CpuUse c3 = cpu_use_now();
    r.rem = phase_between(s1, e.stats(), t_rem, n_remove);
    set_cpu_use(r.rem, c2, c3);
    r.rem.errors = errors.count.load() - r.ins.errors;
  });
}

// pdt: a mixed stream (insertions and remove_insertion) replayed as one phase.
Result run_pdt_stream(const pdt::OpStream& s, unsigned threads, Balance balance = Balance::recut) {
  return with_engine(balance == Balance::recut ? "pdt" : balance == Balance::steal ? "pdt_norecut" : "pdt_nosteal",
                     *s.box, threads,
                     [&](pdt::Triangulation&, pdt::Engine& e, ErrorSink& errors, Result& r) {
    const pdt::EngineStats s0 = e.stats();
    const CpuUse c0 = cpu_use_now();
    Stopwatch sw;
    for (const pdt::Operation& op : s.ops) {
      if (op.kind == pdt::Operation::Kind::insert)
        (void)e.insert(op.point, errors.callback());
      else
        e.remove_insertion(op.target, errors.callback());  // tickets number the insertions from 0, as the stream does
    }
    e.drain();
    const double seconds = sw.seconds();
    const CpuUse c1 = cpu_use_now();
    r.mixed = phase_between(s0, e.stats(), seconds, s.ops.size());
    set_cpu_use(r.mixed, c0, c1);
    r.mixed.errors = errors.count.load();
  }, balance);
}

// CGAL's runs in the Result form the tables and the CSV take.
Result from_cgal(const char* impl, unsigned threads, const CgalRun& c, std::size_t ops_insert, std::size_t ops_remove,
                 bool mixed = false) {
  Result r;
  r.impl = impl;
  r.threads = threads;
  r.shape = c.shape;
  if (mixed) {
    r.mixed = {true, c.mixed_seconds, ops_insert + ops_remove};
  } else {
    r.ins = {true, c.insert_seconds, ops_insert};
    r.rem = {true, c.remove_seconds, ops_remove};
  }
  return r;
}

// ---- output -------------------------------------------------------------------
struct Csv {
  std::ofstream f;
  bool on = false;
  void open(const std::string& path) {
    if (path.empty()) return;
    f.open(path);
    if (!f) throw pdt::Error(pdt::ErrorCode::io_failure, "cannot write " + path);
    on = true;
    f << "experiment,dist,points,impl,phase,threads,blocks_per_axis,ops,seconds,speedup1,speedup2,"
         "cgal_par_over_pdt,max_rollbacks_per_completed_pct,rollbacks,sleeps,seconds_asleep,deferred,"
         "global_operations,busy_workers,failed_operations,bytes_per_tet,finite_cells,steals,imbalance,recuts,"
         "cpu_user_seconds,cpu_sys_seconds,minor_faults,seconds_idle\n";
  }
  // base1: pdt's 1-thread time of the phase; cgal: CGAL seq time; par: CGAL par time at this T (0: none).
  void row(const std::string& experiment, const std::string& dist, std::uint64_t points, const Result& r,
           const char* phase_name, const Phase& p, double base1, double cgal, double par) {
    if (!on || !p.ran) return;
    const bool is_pdt = r.impl.rfind("pdt", 0) == 0;
    char buf[1024];
    auto ratio = [&](double num, double den) -> std::string {
      if (num <= 0 || den <= 0) return "";
      char b[32];
      std::snprintf(b, sizeof b, "%.4f", num / den);
      return b;
    };
    std::string s1 = is_pdt ? ratio(base1, p.seconds) : "";
    std::string s2 = is_pdt ? ratio(cgal, p.seconds) : "";
    std::string s3 = is_pdt ? ratio(par, p.seconds) : "";
    std::snprintf(buf, sizeof buf, "%s,%s,%llu,%s,%s,%u,%u,%llu,%.6f,%s,%s,%s,", experiment.c_str(), dist.c_str(),
                  static_cast<unsigned long long>(points), r.impl.c_str(), phase_name, r.threads, r.blocks,
                  static_cast<unsigned long long>(p.ops), p.seconds, s1.c_str(), s2.c_str(), s3.c_str());
    f << buf;
    if (is_pdt) {
      std::snprintf(buf, sizeof buf, "%.6f,%llu,%llu,%.6f,%llu,%llu,%u,%llu,", p.max_rb_pct,
                    static_cast<unsigned long long>(p.rollbacks), static_cast<unsigned long long>(p.sleeps),
                    p.seconds_asleep, static_cast<unsigned long long>(p.deferred),
                    static_cast<unsigned long long>(p.global_ops), p.busy_workers,
                    static_cast<unsigned long long>(p.errors));
      f << buf;
    } else {
      f << ",,,,,,,,";
    }
    if (is_pdt && &p == &r.ins)
      f << r.bytes_per_tet;
    f << "," << (&p == &r.ins ? r.shape.cells_after_insert : r.shape.finite_cells) << ",";
    if (is_pdt) f << p.steals << "," << p.imbalance << "," << p.recuts;
    else f << ",,";  // every row as many fields as the header
    f << ",";
    if (is_pdt) f << p.cpu_user << "," << p.cpu_sys << "," << p.minor_faults << "," << p.seconds_idle;
    else f << ",,,";
    f << "\n";
    f.flush();
  }
};

// Compares a final state with CGAL sequential's; prints MISMATCH and returns false if they differ.
bool check(const char* what, unsigned threads, const Shape& s, const Shape& ref, bool check_insert = true) {
  const bool ok = s.finite_cells == ref.finite_cells && s.vertices == ref.vertices &&
                  (!check_insert || s.cells_after_insert == ref.cells_after_insert);
  if (!ok && check_insert)
    std::printf(
        "  MISMATCH: %s with %u thread(s): finite cells after insertion %zu (CGAL seq %zu), at the end %zu (CGAL seq "
        "%zu), vertices at the end %zu (CGAL seq %zu)\n",
        what, threads, s.cells_after_insert, ref.cells_after_insert, s.finite_cells, ref.finite_cells, s.vertices,
        ref.vertices);
  else if (!ok)
    std::printf("  MISMATCH: %s with %u thread(s): finite cells at the end %zu (CGAL seq %zu), vertices at the end %zu "
                "(CGAL seq %zu)\n",
                what, threads, s.finite_cells, ref.finite_cells, s.vertices, ref.vertices);
  return ok;
}

// pdt operations that failed (an error in their OpResult): printed loudly, counted as a mismatch.
std::string error_note(const char* what, const Result& r) {
  const std::uint64_t n = r.ins.errors + r.rem.errors + r.mixed.errors;
  if (n == 0) return "";
  char b[256];
  std::snprintf(b, sizeof b, "  MISMATCH: %s with %u thread(s): %llu operation(s) FAILED; first: ", what, r.threads,
                static_cast<unsigned long long>(n));
  return b + r.first_error + "\n";
}
bool check_errors(const char* what, const Result& r) {
  const std::string note = error_note(what, r);
  std::fputs(note.c_str(), stdout);
  return note.empty();
}

// ---- experiments ----------------------------------------------------------------
// Tables 2-4: one distribution. Returns the number of mismatches.
int main_table(const Options& o, pdt::Distribution dist, Csv& csv) {
  const std::string name = pdt::to_string(dist);
  // Named, not bound: a lambda cannot capture a structured binding before Clang 16.
  const PointSet generated = generated_points(dist, o.points, o.seed);
  const std::vector<pdt::Point3>& pts = generated.points;
  const pdt::Box& box = generated.box;
  const std::size_t n_remove = static_cast<std::size_t>(o.remove_fraction * double(pts.size()));
  const std::vector<char> cgal_removes = last_removals(pts, n_remove);

  progress("[%s] CGAL sequential...\n", name.c_str());
  const Result seq = isolated(name + ": CGAL sequential", config_timeout, [&] {
    return from_cgal("cgal_seq", 1, cgal_sequential(pts, cgal_removes), pts.size(), n_remove);
  });
  std::vector<Result> mine, batch, par;
  for (unsigned t : o.threads) {
    const std::string with = " with " + std::to_string(t) + " thread(s)";
    progress("[%s] pdt, %u thread(s)...\n", name.c_str(), t);
    mine.push_back(isolated(name + ": pdt" + with, config_timeout,
                            [&] { return run_pdt(pts, box, n_remove, t, false); }));
    progress("[%s] pdt batch, %u thread(s)...\n", name.c_str(), t);
    batch.push_back(isolated(name + ": pdt batch" + with, config_timeout,
                             [&] { return run_pdt(pts, box, n_remove, t, true); }));
    if (o.cgal_parallel) {
      progress("[%s] CGAL parallel, %u thread(s)...\n", name.c_str(), t);
      par.push_back(isolated(name + ": CGAL parallel" + with, config_timeout, [&] {
        return from_cgal("cgal_par", t, cgal_parallel(pts, box, cgal_removes, t), pts.size(), n_remove);
      }));
    }
  }

  std::printf("\n== %s: %zu points inserted, then the first %zu removed (box [%g,%g]x[%g,%g]x[%g,%g]) ==\n",
              name.c_str(), pts.size(), n_remove, box.lo.x, box.hi.x, box.lo.y, box.hi.y, box.lo.z, box.hi.z);
  const std::size_t nt = o.threads.size();
  Table tab({"Insertions", "Removals"}, o.threads);
  auto row = [&](const std::string& label, auto cell) {
    std::vector<std::string> cells;
    for (int ph = 0; ph < 2; ++ph)
      for (std::size_t i = 0; i < nt; ++i) cells.push_back(cell(ph, i));
    tab.add(label, cells);
  };
  auto ph_of = [](const Result& r, int ph) -> const Phase& { return ph == 0 ? r.ins : r.rem; };
  row("Time (s)", [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(mine[i], ph).seconds); });
  row("Speedup1 (pdt 1 thread / pdt)", [&](int ph, std::size_t i) {
    return fmt_ratio(ph_of(mine[0], ph).seconds, ph_of(mine[i], ph).seconds);
  });
  row("Max #Rollbacks/#compl.ops (%)", [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(mine[i], ph).max_rb_pct); });
  row("Rollbacks (total)", [&](int ph, std::size_t i) { return fmt_u(ph_of(mine[i], ph).rollbacks); });
  row("Sleeps (total)", [&](int ph, std::size_t i) { return fmt_u(ph_of(mine[i], ph).sleeps); });
  row("Seconds asleep (total)", [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(mine[i], ph).seconds_asleep); });
  row("Workers idle: idle / (time*T) (%)", [&](int ph, std::size_t i) { return fmt_idle(ph_of(mine[i], ph), mine[i].threads); });
  row("CPU busy: user+sys / (time*T) (%)", [&](int ph, std::size_t i) { return fmt_busy(ph_of(mine[i], ph), mine[i].threads); });
  row("System share of CPU (%)", [&](int ph, std::size_t i) { return fmt_sys(ph_of(mine[i], ph)); });
  row("Minor page faults (thousands)",
      [&](int ph, std::size_t i) { return fmt("%.0f", double(ph_of(mine[i], ph).minor_faults) / 1e3); });
  row("Global operations", [&](int ph, std::size_t i) { return fmt_u(ph_of(mine[i], ph).global_ops); });
  row("Workers with work", [&](int ph, std::size_t i) {
    return fmt_u(ph_of(mine[i], ph).busy_workers) + "/" + fmt_u(mine[i].threads);
  });
  row("Failed operations", [&](int ph, std::size_t i) { return fmt_u(ph_of(mine[i], ph).errors); });
  row("CGAL seq time (s)", [&](int ph, std::size_t i) { return i == 0 ? fmt("%.3f", ph_of(seq, ph).seconds) : "-"; });
  row("Speedup2 (CGAL seq / pdt)", [&](int ph, std::size_t i) {
    return fmt_ratio(ph_of(seq, ph).seconds, ph_of(mine[i], ph).seconds);
  });
  row("pdt batch time (s)", [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(batch[i], ph).seconds); });
  row("Batch speedup1 (batch 1 thread / batch)", [&](int ph, std::size_t i) {
    return fmt_ratio(ph_of(batch[0], ph).seconds, ph_of(batch[i], ph).seconds);
  });
  row("Batch max #Rollbacks/#compl.ops (%)",
      [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(batch[i], ph).max_rb_pct); });
  if (o.cgal_parallel) {
    row("CGAL parallel time (s)", [&](int ph, std::size_t i) { return fmt("%.3f", ph_of(par[i], ph).seconds); });
    row("CGAL parallel / pdt", [&](int ph, std::size_t i) {
      return fmt_ratio(ph_of(par[i], ph).seconds, ph_of(mine[i], ph).seconds);
    });
    row("CGAL parallel / pdt batch", [&](int ph, std::size_t i) {
      return fmt_ratio(ph_of(par[i], ph).seconds, ph_of(batch[i], ph).seconds);
    });
  }
  row("pdt bytes/tet (after insertions)",
      [&](int ph, std::size_t i) { return ph == 0 ? fmt("%.1f", mine[i].bytes_per_tet) : "-"; });
  row("Peak MiB: pdt / pdt batch",
      [&](int ph, std::size_t i) { return ph == 0 ? fmt("%.0f", mine[i].peak_mib) + " / " + fmt("%.0f", batch[i].peak_mib) : "-"; });
  if (o.cgal_parallel)
    row("Peak MiB: CGAL parallel", [&](int ph, std::size_t i) { return ph == 0 ? fmt("%.0f", par[i].peak_mib) : "-"; });
  tab.print();
  std::printf("  blocks per axis:");
  for (const auto& r : mine) std::printf(" %u (T=%u)", r.blocks, r.threads);
  std::printf("\n  finite cells after insertion %zu, at the end %zu, vertices at the end %zu (CGAL seq)\n",
              seq.shape.cells_after_insert, seq.shape.finite_cells, seq.shape.vertices);

  int bad = 0;
  for (const auto& r : mine) bad += !check("pdt", r.threads, r.shape, seq.shape) + !check_errors("pdt", r);
  for (const auto& r : batch)
    bad += !check("pdt batch", r.threads, r.shape, seq.shape) + !check_errors("pdt batch", r);
  for (const auto& r : par) bad += !check("CGAL parallel", r.threads, r.shape, seq.shape);
  std::printf("  check: %s\n", bad ? "MISMATCH (see above)" : "every final triangulation has CGAL seq's cell and vertex counts");
  std::printf("  peak MiB of CGAL seq's process: %.0f (each configuration runs in a process of its own)\n",
              seq.peak_mib);

  for (std::size_t i = 0; i < nt; ++i) {
    const double p0 = o.cgal_parallel ? par[i].ins.seconds : 0, p1 = o.cgal_parallel ? par[i].rem.seconds : 0;
    csv.row("main", name, pts.size(), mine[i], "insert", mine[i].ins, mine[0].ins.seconds, seq.ins.seconds, p0);
    csv.row("main", name, pts.size(), mine[i], "remove", mine[i].rem, mine[0].rem.seconds, seq.rem.seconds, p1);
    csv.row("main", name, pts.size(), batch[i], "insert", batch[i].ins, batch[0].ins.seconds, seq.ins.seconds, p0);
    csv.row("main", name, pts.size(), batch[i], "remove", batch[i].rem, batch[0].rem.seconds, seq.rem.seconds, p1);
  }
  csv.row("main", name, pts.size(), seq, "insert", seq.ins, 0, 0, 0);
  csv.row("main", name, pts.size(), seq, "remove", seq.rem, 0, 0, 0);
  for (const auto& r : par) {
    csv.row("main", name, pts.size(), r, "insert", r.ins, 0, 0, 0);
    csv.row("main", name, pts.size(), r, "remove", r.rem, 0, 0, 0);
  }
  return bad;
}

// Table 1 (§3.3): 3,000 normal points, insert all then remove all.
int extreme_table(const Options& o, Csv& csv) {
  const PointSet generated = generated_points(pdt::Distribution::normal, extreme_points, o.seed);
  const std::vector<pdt::Point3>& pts = generated.points;
  const pdt::Box& box = generated.box;
  const unsigned tmax = *std::max_element(o.threads.begin(), o.threads.end());
  std::vector<unsigned> ts{1};
  if (tmax > 1) ts.push_back(tmax);
  progress("[extreme] CGAL sequential...\n");
  const Result seq = isolated("extreme case: CGAL sequential", config_timeout, [&] {
    return from_cgal("cgal_seq", 1, cgal_sequential(pts, last_removals(pts, pts.size())), pts.size(), pts.size());
  });
  progress("[extreme] pdt, %zu points, threads 1 and %u, %d runs each...\n", pts.size(), tmax, extreme_repeats);

  // Per thread count: median time of each phase; rollback ratio: the worst run.
  std::vector<Result> res;
  std::string notes;  // printed after the table
  int bad = 0;
  for (unsigned t : ts) {
    std::vector<Result> runs;
    for (int k = 0; k < extreme_repeats; ++k) {
      const double limit = config_timeout > 0 ? std::min(config_timeout, extreme_run_timeout) : 0;
      runs.push_back(isolated("extreme case: pdt with " + std::to_string(t) + " thread(s), run " + std::to_string(k + 1),
                              limit, [&] { return run_pdt(pts, box, pts.size(), t, false); }));
    }
    Result agg = runs[0];
    auto median = [&](auto get) {
      std::vector<double> v;
      for (const auto& r : runs) v.push_back(get(r));
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    agg.ins.seconds = median([](const Result& r) { return r.ins.seconds; });
    agg.rem.seconds = median([](const Result& r) { return r.rem.seconds; });
    agg.ins.sleeps = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.ins.sleeps); }));
    agg.rem.sleeps = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.rem.sleeps); }));
    agg.ins.rollbacks = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.ins.rollbacks); }));
    agg.rem.rollbacks = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.rem.rollbacks); }));
    agg.ins.global_ops = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.ins.global_ops); }));
    agg.rem.global_ops = static_cast<std::uint64_t>(median([](const Result& r) { return double(r.rem.global_ops); }));
    agg.ins.max_rb_pct = agg.rem.max_rb_pct = 0;
    agg.ins.errors = agg.rem.errors = 0;
    for (const auto& r : runs) {
      agg.ins.errors += r.ins.errors;
      agg.rem.errors += r.rem.errors;
      if (agg.first_error.empty()) agg.first_error = r.first_error;
      agg.ins.max_rb_pct = std::max(agg.ins.max_rb_pct, r.ins.max_rb_pct);
      agg.rem.max_rb_pct = std::max(agg.rem.max_rb_pct, r.rem.max_rb_pct);
      if (r.shape.vertices != 0 || r.shape.finite_cells != 0 ||
          r.shape.cells_after_insert != seq.shape.cells_after_insert) {
        char b[512];
        std::snprintf(b, sizeof b,
                      "  MISMATCH: extreme case with %u thread(s): %zu finite cells after insertion (CGAL seq %zu), "
                      "%zu vertices and %zu finite cells left at the end (want 0)\n",
                      t, r.shape.cells_after_insert, seq.shape.cells_after_insert, r.shape.vertices,
                      r.shape.finite_cells);
        notes += b;
        ++bad;
      }
    }
    const std::string note = error_note("extreme case (all runs)", agg);
    notes += note;
    bad += !note.empty();
    res.push_back(agg);
  }

  std::printf("\n== extreme (§3.3, Table 1): %zu normal points inserted, then all removed; median of %d runs, "
              "rollbacks: worst run ==\n",
              pts.size(), extreme_repeats);
  Table tab({"Insertions", "Removals"}, ts);
  auto row = [&](const std::string& label, auto cell) {
    std::vector<std::string> cells;
    for (int ph = 0; ph < 2; ++ph)
      for (std::size_t i = 0; i < ts.size(); ++i) cells.push_back(cell(ph, i));
    tab.add(label, cells);
  };
  auto ph_of = [](const Result& r, int ph) -> const Phase& { return ph == 0 ? r.ins : r.rem; };
  row("Time (s)", [&](int ph, std::size_t i) { return fmt("%.4f", ph_of(res[i], ph).seconds); });
  row("Speedup", [&](int ph, std::size_t i) { return fmt_ratio(ph_of(res[0], ph).seconds, ph_of(res[i], ph).seconds); });
  row("Max #Rollbacks/#compl.ops (%)", [&](int ph, std::size_t i) { return fmt("%.1f", ph_of(res[i], ph).max_rb_pct); });
  row("Rollbacks (total, median)", [&](int ph, std::size_t i) { return fmt_u(ph_of(res[i], ph).rollbacks); });
  row("Sleeps (total, median)", [&](int ph, std::size_t i) { return fmt_u(ph_of(res[i], ph).sleeps); });
  row("Global operations", [&](int ph, std::size_t i) { return fmt_u(ph_of(res[i], ph).global_ops); });
  row("Failed operations (all runs)", [&](int ph, std::size_t i) { return fmt_u(ph_of(res[i], ph).errors); });
  row("CGAL seq time (s)", [&](int ph, std::size_t i) { return i == 0 ? fmt("%.4f", ph_of(seq, ph).seconds) : "-"; });
  row("Speedup2 (CGAL seq / pdt)",
      [&](int ph, std::size_t i) { return fmt_ratio(ph_of(seq, ph).seconds, ph_of(res[i], ph).seconds); });
  tab.print();
  std::fputs(notes.c_str(), stdout);
  std::printf("  finite cells after insertion %zu (CGAL seq); check: %s\n", seq.shape.cells_after_insert,
              bad ? "MISMATCH (see above)" : "every run has CGAL's cells after insertion and ends empty");
  for (const auto& r : res) {
    csv.row("extreme", "normal", pts.size(), r, "insert", r.ins, res[0].ins.seconds, seq.ins.seconds, 0);
    csv.row("extreme", "normal", pts.size(), r, "remove", r.rem, res[0].rem.seconds, seq.rem.seconds, 0);
  }
  csv.row("extreme", "normal", pts.size(), seq, "insert", seq.ins, 0, 0, 0);
  csv.row("extreme", "normal", pts.size(), seq, "remove", seq.rem, 0, 0, 0);
  return bad;
}

// A refiner-like stream: removals interleaved with the insertions.
// o.points insertions of dist with interleaved_fraction of them undone, interleaved.
pdt::OpStream interleaved_stream(const Options& o, pdt::Distribution dist) {
  pdt::GenerateOptions g;
  g.dist = dist;
  g.points = o.points;
  g.seed = o.seed;
  g.remove_fraction = interleaved_fraction;
  g.removal_order = pdt::RemovalOrder::interleaved;
  return pdt::generate(g);
}

int interleaved_table(const Options& o, pdt::Distribution dist, Csv& csv) {
  const std::string name = pdt::to_string(dist);
  const pdt::OpStream s = interleaved_stream(o, dist);

  progress("[%s interleaved] CGAL sequential...\n", name.c_str());
  const Result seq = isolated(name + " interleaved: CGAL sequential", config_timeout, [&] {
    return from_cgal("cgal_seq", 1, cgal_sequential_stream(s), s.insert_count(), s.remove_count(), true);
  });
  std::vector<Result> mine;
  for (unsigned t : o.threads) {
    progress("[%s interleaved] pdt, %u thread(s)...\n", name.c_str(), t);
    mine.push_back(isolated(name + " interleaved: pdt with " + std::to_string(t) + " thread(s)", config_timeout,
                            [&] { return run_pdt_stream(s, t); }));
  }

  std::printf("\n== %s interleaved: %zu insertions and %zu removals mixed (RemovalOrder::interleaved) ==\n",
              name.c_str(), s.insert_count(), s.remove_count());
  Table tab({"Mixed stream"}, o.threads);
  auto row = [&](const std::string& label, auto cell) {
    std::vector<std::string> cells;
    for (std::size_t i = 0; i < mine.size(); ++i) cells.push_back(cell(i));
    tab.add(label, cells);
  };
  row("Time (s)", [&](std::size_t i) { return fmt("%.3f", mine[i].mixed.seconds); });
  row("Speedup1 (pdt 1 thread / pdt)", [&](std::size_t i) { return fmt_ratio(mine[0].mixed.seconds, mine[i].mixed.seconds); });
  row("Max #Rollbacks/#compl.ops (%)", [&](std::size_t i) { return fmt("%.3f", mine[i].mixed.max_rb_pct); });
  row("Rollbacks (total)", [&](std::size_t i) { return fmt_u(mine[i].mixed.rollbacks); });
  row("Deferred removals (total)", [&](std::size_t i) { return fmt_u(mine[i].mixed.deferred); });
  row("Sleeps (total)", [&](std::size_t i) { return fmt_u(mine[i].mixed.sleeps); });
  row("Workers idle: idle / (time*T) (%)", [&](std::size_t i) { return fmt_idle(mine[i].mixed, mine[i].threads); });
  row("CPU busy: user+sys / (time*T) (%)", [&](std::size_t i) { return fmt_busy(mine[i].mixed, mine[i].threads); });
  row("System share of CPU (%)", [&](std::size_t i) { return fmt_sys(mine[i].mixed); });
  row("Minor page faults (thousands)", [&](std::size_t i) { return fmt("%.0f", double(mine[i].mixed.minor_faults) / 1e3); });
  row("Global operations", [&](std::size_t i) { return fmt_u(mine[i].mixed.global_ops); });
  row("Failed operations", [&](std::size_t i) { return fmt_u(mine[i].mixed.errors); });
  row("CGAL seq time (s)", [&](std::size_t i) { return i == 0 ? fmt("%.3f", seq.mixed.seconds) : "-"; });
  row("Speedup2 (CGAL seq / pdt)", [&](std::size_t i) { return fmt_ratio(seq.mixed.seconds, mine[i].mixed.seconds); });
  tab.print();
  int bad = 0;
  for (const auto& r : mine)
    bad += !check("pdt interleaved", r.threads, r.shape, seq.shape, false) + !check_errors("pdt interleaved", r);
  std::printf("  final finite cells %zu, vertices %zu (CGAL seq); check: %s\n", seq.shape.finite_cells,
              seq.shape.vertices, bad ? "MISMATCH (see above)" : "pdt matches at every thread count");
  for (const auto& r : mine)
    csv.row("interleaved", name, s.insert_count(), r, "mixed", r.mixed, mine[0].mixed.seconds, seq.mixed.seconds, 0);
  csv.row("interleaved", name, s.insert_count(), seq, "mixed", seq.mixed, 0, 0, 0);
  return bad;
}

// Load balance (issue 11): streams whose work concentrates (corner, kuzmin)
// or moves (front_x/y/z), or a refiner's trace, replayed as one mixed phase
// with stealing and recuts (the default), stealing only, and neither.
int skewed_table(const Options& o, const std::string& name, const pdt::OpStream& s, Csv& csv) {
  progress("[%s] CGAL sequential...\n", name.c_str());
  const Result seq = isolated(name + ": CGAL sequential", config_timeout, [&] {
    return from_cgal("cgal_seq", 1, cgal_sequential_stream(s), s.insert_count(), s.remove_count(), true);
  });
  const Balance modes[3] = {Balance::recut, Balance::steal, Balance::none};
  const char* mode_names[3] = {"stealing + recuts", "stealing only", "neither"};
  std::vector<Result> runs[3];
  for (unsigned t : o.threads) {
    for (int m = 0; m < 3; ++m) {
      progress("[%s] pdt, %u thread(s), %s...\n", name.c_str(), t, mode_names[m]);
      runs[m].push_back(isolated(name + ": pdt with " + std::to_string(t) + " thread(s), " + mode_names[m],
                                 config_timeout, [&] { return run_pdt_stream(s, t, modes[m]); }));
    }
  }
  std::printf("\n== skewed %s: %zu insertions and %zu removals, one mixed phase ==\n", name.c_str(),
              s.insert_count(), s.remove_count());
  Table tab({"Stealing + recuts (default)", "Stealing only", "Static (paper)"}, o.threads);
  auto of = [&](int g, std::size_t i) -> const Result& { return runs[g][i]; };
  tab.row("Time (s)", [&](int g, std::size_t i) { return fmt("%.3f", of(g, i).mixed.seconds); });
  tab.row("Speedup1 (pdt 1 worker / pdt)",
          [&](int g, std::size_t i) { return fmt_ratio(of(g, 0).mixed.seconds, of(g, i).mixed.seconds); });
  tab.row("Imbalance (max/mean completed)", [&](int g, std::size_t i) { return fmt("%.2f", of(g, i).mixed.imbalance); });
  tab.row("Steals", [&](int g, std::size_t i) { return fmt_u(of(g, i).mixed.steals); });
  tab.row("Recuts", [&](int g, std::size_t i) { return fmt_u(of(g, i).mixed.recuts); });
  tab.row("Workers with work", [&](int g, std::size_t i) {
    return fmt_u(of(g, i).mixed.busy_workers) + "/" + fmt_u(of(g, i).threads);
  });
  tab.row("Rollbacks (total)", [&](int g, std::size_t i) { return fmt_u(of(g, i).mixed.rollbacks); });
  tab.row("Max #Rollbacks/#compl.ops (%)", [&](int g, std::size_t i) { return fmt("%.3f", of(g, i).mixed.max_rb_pct); });
  tab.row("Seconds asleep (total)", [&](int g, std::size_t i) { return fmt("%.3f", of(g, i).mixed.seconds_asleep); });
  tab.row("Workers idle: idle / (time*T) (%)", [&](int g, std::size_t i) { return fmt_idle(of(g, i).mixed, of(g, i).threads); });
  tab.row("CPU busy: user+sys / (time*T) (%)",
          [&](int g, std::size_t i) { return fmt_busy(of(g, i).mixed, of(g, i).threads); });
  tab.row("System share of CPU (%)", [&](int g, std::size_t i) { return fmt_sys(of(g, i).mixed); });
  tab.row("Minor page faults (thousands)",
          [&](int g, std::size_t i) { return fmt("%.0f", double(of(g, i).mixed.minor_faults) / 1e3); });
  tab.row("Global operations", [&](int g, std::size_t i) { return fmt_u(of(g, i).mixed.global_ops); });
  tab.row("Failed operations", [&](int g, std::size_t i) { return fmt_u(of(g, i).mixed.errors); });
  tab.row("CGAL seq time (s)", [&](int, std::size_t i) { return i == 0 ? fmt("%.3f", seq.mixed.seconds) : "-"; });
  tab.row("Speedup2 (CGAL seq / pdt)",
          [&](int g, std::size_t i) { return fmt_ratio(seq.mixed.seconds, of(g, i).mixed.seconds); });
  tab.print();
  int bad = 0;
  for (const auto& rs : runs)
    for (const auto& r : rs)
      bad += !check(r.impl.c_str(), r.threads, r.shape, seq.shape, false) + !check_errors("pdt skewed", r);
  std::printf("  final finite cells %zu, vertices %zu (CGAL seq); check: %s\n", seq.shape.finite_cells,
              seq.shape.vertices, bad ? "MISMATCH (see above)" : "pdt matches at every worker count, in every mode");
  for (std::size_t i = 0; i < o.threads.size(); ++i)
    for (const auto& rs : runs)
      csv.row("skewed", name, s.insert_count(), rs[i], "mixed", rs[i].mixed, rs[0].mixed.seconds, seq.mixed.seconds, 0);
  csv.row("skewed", name, s.insert_count(), seq, "mixed", seq.mixed, 0, 0, 0);
  return bad;
}

int skewed_tables(const Options& o, Csv& csv) {
  int bad = 0;
  for (pdt::Distribution d : {pdt::Distribution::corner, pdt::Distribution::kuzmin, pdt::Distribution::front_x,
                              pdt::Distribution::front_y, pdt::Distribution::front_z})
    bad += skewed_table(o, pdt::to_string(d), interleaved_stream(o, d), csv);
  if (!o.trace.empty()) {
    const pdt::OpStream s = pdt::read_ops(o.trace);
    if (!s.box) throw pdt::Error(pdt::ErrorCode::invalid_argument, o.trace + ": the trace declares no box");
    bad += skewed_table(o, "trace", s, csv);
  }
  return bad;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  std::vector<pdt::Distribution> dists;
  try {
    for (const auto& d : o.dists)
      if (d != "none") dists.push_back(pdt::parse_distribution(d));
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 2;
  }
  const unsigned tmax = *std::max_element(o.threads.begin(), o.threads.end());
  const int cpus = affinity_cpus();
  // Let an arena of tmax really get tmax threads, even beyond the core count
  // (oneTBB's default cap is the hardware concurrency); set in each
  // configuration's process (isolated), where the threads start.
  tbb_parallelism = std::max<std::size_t>(tmax, std::thread::hardware_concurrency());
  config_timeout = o.timeout;

  std::printf("bench_parallel: %llu points, threads", static_cast<unsigned long long>(o.points));
  for (unsigned t : o.threads) std::printf(" %u", t);
  std::printf(", remove fraction %g, seed %llu\n", o.remove_fraction, static_cast<unsigned long long>(o.seed));
  std::printf("machine: %u hardware threads (nproc %d), CPU %s\n", std::thread::hardware_concurrency(), cpus,
              cpu_model().c_str());
  std::printf("pdt allocator: %s; oneTBB %s; CGAL %s (its Parallel_tag containers on tbbmalloc)\n",
              pdt::allocator_name(), TBB_VERSION_STRING, CGAL_VERSION_STR);
  std::printf("pdt: Engine in tbb::task_arena(T), options.threads = T; insert(p, cb) all + drain(), then "
              "remove_insertion(first F*N, cb) + drain(); cb only counts failed operations\n");
  std::printf("CGAL seq: Delaunay_triangulation_3<Epick, Default, Fast_location>, insert(p) one at a time (no spatial "
              "sort), remove(vh) one at a time\n");
  if (o.cgal_parallel)
    std::printf("CGAL parallel: Parallel_tag TDS + Spatial_lock_grid_3<Tag_priority_blocking> (%d cells/axis), "
                "insert(range) (spatially sorted by CGAL, sort timed), remove(range), in tbb::task_arena(T)\n",
                lock_grid_cells_per_axis);
  std::printf("Each configuration runs in a process of its own (its pages and its peak memory are its own).\n");
  if (cpus > 0 && tmax > static_cast<unsigned>(cpus))
    std::printf("note: %u threads asked for but only %d CPUs available: those runs are oversubscribed\n", tmax, cpus);
  std::fflush(stdout);

  int mismatches = 0;
  try {
    Csv csv;
    csv.open(o.csv);
    if (o.main_tables)
      for (pdt::Distribution d : dists) mismatches += main_table(o, d, csv);
    if (o.interleaved)
      for (pdt::Distribution d : dists) mismatches += interleaved_table(o, d, csv);
    if (o.skewed) mismatches += skewed_tables(o, csv);
    // Last: the case most likely to expose an engine livelock (see --timeout).
    if (o.extreme) mismatches += extreme_table(o, csv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 2;
  }
  std::printf("\npeak RSS of the largest configuration's process: %.1f MiB\n", largest_peak_kib / 1024.0);
  if (mismatches)
    std::printf("\n%d MISMATCH(ES): a final triangulation differs from CGAL's, or pdt operations failed\n", mismatches);
  return mismatches ? 1 : 0;
}
