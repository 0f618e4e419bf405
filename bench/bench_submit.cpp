// SPDX-License-Identifier: MIT
// bench_submit: one thread feeding an Engine one operation at a time, as
// bench_parallel's pdt rows do (insert(p, cb) for every point, drain(), then
// remove_insertion of the first 10%), with what tells whether the submitting
// thread or the workers set the pace: how long the submitting loop took and
// how many insertions were done when it ended (all of them: the workers kept
// up, and the loop's time is the insertion's time), the workers' idle share,
// CPU busy and system share, page faults. No CGAL: cheap enough to compare
// builds side by side on one machine (each configuration is one process run
// of this program; the points are pdt::generate's, as bench_parallel's).
//
// Usage: bench_submit [--points N] [--threads 1,16] [--dists uniform]
//                     [--batch] [--repeat R]
// Uses the public API only (pdt/pdt.hpp).
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/task_arena.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "pdt/pdt.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

struct Usage {
  double user = 0, sys = 0;
  long minor_faults = 0;
  static Usage now() {
    rusage r{};
    getrusage(RUSAGE_SELF, &r);
    return {double(r.ru_utime.tv_sec) + 1e-6 * double(r.ru_utime.tv_usec),
            double(r.ru_stime.tv_sec) + 1e-6 * double(r.ru_stime.tv_usec), r.ru_minflt};
  }
};

struct Phase {
  double seconds = 0, idle = 0;
  std::uint64_t rollbacks = 0;
  Usage from, to;
  unsigned threads = 1;
  std::string describe() const {
    const double cpu = (to.user + to.sys) - (from.user + from.sys);
    char out[200];
    std::snprintf(out, sizeof out, "%.3f s, rollbacks %llu, idle %.1f%%, CPU busy %.0f%%, system %.1f%%, faults %ldk",
                  seconds, static_cast<unsigned long long>(rollbacks), 100 * idle / (seconds * threads),
                  100 * cpu / (seconds * threads), cpu > 0 ? 100 * (to.sys - from.sys) / cpu : 0.0,
                  (to.minor_faults - from.minor_faults) / 1000);
    return out;
  }
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::size_t at = 0;
  for (;;) {
    const std::size_t comma = s.find(',', at);
    out.push_back(s.substr(at, comma - at));
    if (comma == std::string::npos) return out;
    at = comma + 1;
  }
}

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "bench_submit: %s\nusage: bench_submit [--points N] [--threads 1,16] [--dists uniform,normal,line] "
               "[--batch] [--repeat R]\n",
               why);
  std::exit(2);
}

void run(const std::vector<pdt::Point3>& points, const pdt::Box& box, const char* dist, unsigned threads, bool batch) {
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, threads);
  pdt::Triangulation t;
  tbb::task_arena arena(static_cast<int>(threads));
  arena.execute([&] {
    pdt::EngineOptions options = pdt::EngineOptions::from_environment();
    options.workers = threads;
    pdt::Engine engine(t, box, options);
    std::atomic<std::uint64_t> done{0}, failed{0};
    auto count = [&](const pdt::OpResult& r) {
      if (r.error) failed.fetch_add(1, std::memory_order_relaxed);
      done.fetch_add(1, std::memory_order_relaxed);
    };
    const std::size_t n_remove = points.size() / 10;
    std::vector<pdt::Engine::Ticket> tickets(n_remove);
    Phase ins, rem;
    ins.threads = rem.threads = threads;
    ins.from = Usage::now();
    const auto t0 = Clock::now();
    if (batch) {
      const pdt::Engine::Ticket first = engine.insert_batch(points, count);
      for (std::size_t k = 0; k < n_remove; ++k) tickets[k] = first + k;
    } else {
      for (std::size_t k = 0; k < points.size(); ++k) {
        const pdt::Engine::Ticket tk = engine.insert(points[k], count);
        if (k < n_remove) tickets[k] = tk;
      }
    }
    const auto t1 = Clock::now();
    const std::uint64_t done_when_submitted = done.load();
    engine.drain();
    const auto t2 = Clock::now();
    ins.to = rem.from = Usage::now();
    const pdt::WorkerStats s1 = engine.stats().total();
    ins.seconds = seconds(t0, t2);
    ins.idle = s1.seconds_idle;
    ins.rollbacks = s1.rollbacks;
    if (batch)
      engine.remove_insertions(tickets, count);
    else
      for (pdt::Engine::Ticket tk : tickets) engine.remove_insertion(tk, count);
    engine.drain();
    const auto t3 = Clock::now();
    rem.to = Usage::now();
    const pdt::WorkerStats s2 = engine.stats().total();
    rem.seconds = seconds(t2, t3);
    rem.idle = s2.seconds_idle - s1.seconds_idle;
    rem.rollbacks = s2.rollbacks - s1.rollbacks;
    std::printf("%-7s %-5s T=%-2u blocks %2u | insert %s; submitting %.3f s, %.1f%% done by then | remove %s | "
                "%zu finite cells%s\n",
                dist, batch ? "batch" : "one", threads, engine.blocks_per_axis(), ins.describe().c_str(),
                seconds(t0, t1), 100.0 * double(done_when_submitted) / double(points.size()),
                rem.describe().c_str(), t.number_of_finite_cells(), failed.load() ? " FAILED OPERATIONS" : "");
    std::fflush(stdout);
    if (failed.load()) std::exit(1);
  });
}

}  // namespace

int main(int argc, char** argv) {
  std::uint64_t n = 1000000;
  std::vector<std::string> threads{"1", "16"}, dists{"uniform"};
  bool batch = false;
  int repeat = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(("missing value after " + a).c_str());
      return argv[++i];
    };
    if (a == "--points")
      n = std::strtoull(value().c_str(), nullptr, 10);
    else if (a == "--threads")
      threads = split(value());
    else if (a == "--dists")
      dists = split(value());
    else if (a == "--batch")
      batch = true;
    else if (a == "--repeat")
      repeat = std::max(1, std::atoi(value().c_str()));
    else
      usage(("unknown option " + a).c_str());
  }
  if (n == 0) usage("--points must be at least 1");
  try {
    for (const std::string& d : dists) {
      pdt::GenerateOptions g;
      g.dist = pdt::parse_distribution(d);
      g.points = n;
      g.seed = 1;
      const pdt::OpStream s = pdt::generate(g);
      std::vector<pdt::Point3> points;
      for (const pdt::Operation& op : s.ops)
        if (op.kind == pdt::Operation::Kind::insert) points.push_back(op.point);
      for (const std::string& tn : threads) {
        const int tc = std::atoi(tn.c_str());
        if (tc < 1) usage(("bad thread count " + tn).c_str());
        for (int r = 0; r < repeat; ++r) run(points, *s.box, d.c_str(), static_cast<unsigned>(tc), batch);
      }
    }
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "bench_submit: %s\n", e.what());
    return 2;
  }
  return 0;
}
