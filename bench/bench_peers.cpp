// SPDX-License-Identifier: MIT
// bench_peers: pdt against its peers, in the same run and on the same points
// (issue 13): CGAL's Delaunay_triangulation_3 (sequential and parallel), HXT
// (gmsh's parallel Delaunay) when this build has it, and pdt (sequential
// batch and the engine's batch). Batch insertion of N points only.
//
//   bench_peers [--points N] [--dists uniform,normal] [--threads 1,2] [--repeat K]
//               [--seed S] [--csv FILE] [--timeout S]
//
// Per distribution, N points from pdt::generate (random order, generated
// once, before the configurations fork), then, each in its own process (fork:
// its peak memory is its own; the parent starts no thread):
//   CGAL batch     Delaunay_triangulation_3<Epick>, insert(first, last)
//   CGAL parallel  over a Parallel_tag TDS with Spatial_lock_grid_3
//                  (as bench_parallel), insert(first, last) in a
//                  tbb::task_arena(T), for each T
//   HXT            hxtDelaunay on an HXTMesh holding the points (HXT's own
//                  entry point, as its Delaunay_CLI and the HXT paper's
//                  figures), options.delaunayThreads = T and
//                  omp_set_num_threads(T), for each T
//   pdt batch      Triangulation::insert_batch(points)
//   pdt engine     Engine(t, box, {workers = T}) in a tbb::task_arena(T):
//                  insert_batch(points), drain(), for each T
// Each spatially sorts the points inside its timing (CGAL's spatial_sort,
// HXT's BRIO); only the insertion is timed: not the generation, not the
// copy of the points into HXT's mesh (its vertex array), not the set-up of
// an engine or a lock grid, not the destruction. CGAL's points go in through
// a converting iterator: its own copy (which it sorts) is the only one.
// Memory: "peak" is the process's VmHWM, reset (/proc/self/clear_refs) when
// the configuration's process starts; "own" is peak minus the resident
// memory at that moment (the program and the generated points), i.e. what
// the configuration added, from which bytes per vertex and per tetrahedron.
// --repeat K runs every configuration K times (interleaved: all
// configurations, K rounds) and reports the medians.
//
// Every configuration must end with CGAL batch's numbers of vertices and
// finite tetrahedra (the Delaunay triangulation of points in general
// position is unique; random doubles are): MISMATCH is printed and the exit
// status is 1 otherwise (also for HXT); a failed configuration prints FAILED
// and exits 1; one running past --timeout prints HANG (its process exits 3).
//
// HXT: Debian 12 has it inside libgmsh (libgmsh-dev 4.8.4) but not its
// headers, which come from gmsh's source package of the same version:
// scripts/install-hxt.sh installs both, then re-run cmake (cmake/PdtHxt.cmake;
// or point PDT_HXT_SOURCE_DIR at a gmsh source tree). Without them this bench
// runs the rest and says "HXT: not available". Licences: CGAL's
// Triangulation_3 and gmsh (HXT) are GPL; they are linked into this bench
// executable only, never into libpdt (MIT).
#include <fcntl.h>
#include <unistd.h>

#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/version.h>
#include <CGAL/version.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
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
#include "pdt/triangulation.hpp"
#include "support/sys_info.hpp"

#ifdef PDT_BENCH_HXT
#include <omp.h>

#include "hxt_tetDelaunay.h"
#endif

namespace {

using namespace pdt_bench;
using pdt::support::Stopwatch;

struct Options {
  std::uint64_t points = 1000000;
  std::vector<std::string> dists{"uniform", "normal"};
  std::vector<unsigned> threads{1, 2};
  std::uint64_t repeat = 1;
  std::uint64_t seed = 1;
  std::string csv;
  double timeout = 600;
};

enum class Peer { cgal_batch, cgal_parallel, hxt, pdt_batch, pdt_engine };

const char* peer_name(Peer p) {
  switch (p) {
    case Peer::cgal_batch: return "CGAL batch";
    case Peer::cgal_parallel: return "CGAL parallel";
    case Peer::hxt: return "HXT";
    case Peer::pdt_batch: return "pdt batch";
    case Peer::pdt_engine: return "pdt engine";
  }
  return "?";
}
const char* peer_key(Peer p) {
  switch (p) {
    case Peer::cgal_batch: return "cgal_batch";
    case Peer::cgal_parallel: return "cgal_parallel";
    case Peer::hxt: return "hxt";
    case Peer::pdt_batch: return "pdt_batch";
    case Peer::pdt_engine: return "pdt_engine";
  }
  return "?";
}

struct Config {
  Peer peer;
  unsigned threads;  // 1 for the sequential ones
  std::string label() const {
    const bool seq = peer == Peer::cgal_batch || peer == Peer::pdt_batch;
    return seq ? std::string(peer_name(peer)) : std::string(peer_name(peer)) + ", " + std::to_string(threads);
  }
};

// What one run of a configuration sends back to the parent (plain data).
struct Outcome {
  double seconds = 0;
  std::uint64_t vertices = 0, finite_cells = 0;
  std::uint64_t base_bytes = 0, peak_bytes = 0;  // VmRSS at the start, VmHWM at the end
};

// The peak (VmHWM) starts again from the current resident memory (Linux >= 4.0).
void reset_peak() {
  const int fd = open("/proc/self/clear_refs", O_WRONLY);
  if (fd < 0) return;
  const ssize_t w = write(fd, "5", 1);
  (void)w;
  close(fd);
}

#ifdef PDT_BENCH_HXT
void hxt_check(HXTStatus s, const char* what) {
  if (s != HXT_STATUS_OK)
    throw pdt::Error(pdt::ErrorCode::invalid_argument, std::string("HXT: ") + what + " failed (status " +
                                                           std::to_string(static_cast<int>(s)) + ")");
}

Outcome run_hxt(const std::vector<pdt::Point3>& pts, unsigned threads) {
  Outcome out;
  omp_set_num_threads(static_cast<int>(threads));  // HXT's parallel loops besides the insertion's own
  HXTMesh* mesh = nullptr;
  hxt_check(hxtMeshCreate(&mesh), "hxtMeshCreate");
  const std::size_t n = pts.size();
  hxt_check(hxtAlignedMalloc(&mesh->vertices.coord, n * 4 * sizeof(double)), "allocating the vertices");
  for (std::size_t i = 0; i < n; ++i) {
    double* c = mesh->vertices.coord + 4 * i;
    c[0] = pts[i].x, c[1] = pts[i].y, c[2] = pts[i].z, c[3] = 0;
  }
  mesh->vertices.num = mesh->vertices.size = static_cast<std::uint32_t>(n);
  // As gmsh's own Delaunay_CLI: an empty mesh, perfect Delaunay (no constraints).
  HXTDelaunayOptions o{};
  o.bbox = nullptr;
  o.nodalSizes = nullptr;
  o.numVerticesInMesh = 0;
  o.insertionFirst = 0;
  o.partitionability = 0;
  o.perfectDelaunay = 1;
  o.verbosity = 0;
  o.reproducible = 0;
  o.delaunayThreads = static_cast<int>(threads);
  Stopwatch sw;
  const HXTStatus s = hxtDelaunay(mesh, &o);
  out.seconds = sw.seconds();
  hxt_check(s, "hxtDelaunay");
  // Ghost tetrahedra (HXT's infinite cells) have HXT_GHOST_VERTEX as their 4th node.
  for (std::uint64_t i = 0; i < mesh->tetrahedra.num; ++i)
    out.finite_cells += mesh->tetrahedra.node[4 * i + 3] != HXT_GHOST_VERTEX;
  out.vertices = mesh->vertices.num;  // the vertices it could not insert are gone from it
  out.peak_bytes = pdt::support::peak_rss_bytes();
  hxt_check(hxtMeshDelete(&mesh), "hxtMeshDelete");
  return out;
}
#endif

// What every pdt run reports once its triangulation is built.
Outcome& finish(Outcome& out, const pdt::Triangulation& t) {
  out.vertices = t.number_of_vertices();
  out.finite_cells = t.number_of_finite_cells();
  out.peak_bytes = pdt::support::peak_rss_bytes();
  return out;
}

Outcome run_pdt_batch(const std::vector<pdt::Point3>& pts) {
  Outcome out;
  pdt::Triangulation t;
  Stopwatch sw;
  (void)t.insert_batch(pts);
  out.seconds = sw.seconds();
  return finish(out, t);
}

Outcome run_pdt_engine(const std::vector<pdt::Point3>& pts, const pdt::Box& box, unsigned threads) {
  Outcome out;
  pdt::Triangulation t;
  {
    tbb::task_arena arena(static_cast<int>(threads));
    arena.execute([&] {
      pdt::EngineOptions opts = pdt::EngineOptions::from_environment();
      opts.workers = threads;
      pdt::Engine e(t, box, opts);
      Stopwatch sw;
      (void)e.insert_batch(pts);
      e.drain();
      out.seconds = sw.seconds();
    });
  }
  return finish(out, t);
}

Outcome run_cgal(const std::vector<pdt::Point3>& pts, const pdt::Box& box, unsigned threads) {
  Outcome out;
  const CgalInsert r = cgal_range_insert(pts, box, threads);
  out.seconds = r.seconds;
  out.vertices = r.vertices;
  out.finite_cells = r.finite_cells;
  out.peak_bytes = pdt::support::peak_rss_bytes();  // the triangulation is gone: its peak is not
  return out;
}

// One run of a configuration, in the child process.
Outcome run_config(const Config& c, const PointSet& ps, double timeout) {
  reset_peak();
  const std::uint64_t base = pdt::support::current_rss_bytes();
  Watchdog dog;
  WatchdogGuard guard(&dog, c.label(), timeout);
  // Let an arena of T threads really get T threads, even beyond the core count.
  const std::size_t parallelism = std::max<std::size_t>(c.threads, std::thread::hardware_concurrency());
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, parallelism);
  Outcome out;
  switch (c.peer) {
    case Peer::cgal_batch: out = run_cgal(ps.points, ps.box, 0); break;
    case Peer::cgal_parallel: out = run_cgal(ps.points, ps.box, c.threads); break;
    case Peer::pdt_batch: out = run_pdt_batch(ps.points); break;
    case Peer::pdt_engine: out = run_pdt_engine(ps.points, ps.box, c.threads); break;
    case Peer::hxt:
#ifdef PDT_BENCH_HXT
      out = run_hxt(ps.points, c.threads);
#endif
      break;
  }
  out.base_bytes = base;
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// A configuration's K runs, summarised.
struct Summary {
  Config config;
  bool ok = false;
  std::string error;
  double seconds = 0, seconds_min = 0, seconds_max = 0;
  double peak = 0, own = 0;  // bytes, medians
  std::uint64_t vertices = 0, finite_cells = 0;
  bool counts_vary = false;  // the runs disagree with each other
};

Summary summarise(const Config& c, const std::vector<Outcome>& runs, const std::string& error) {
  Summary s;
  s.config = c;
  s.error = error;
  s.ok = error.empty() && !runs.empty();
  if (!s.ok) return s;
  std::vector<double> secs, peaks, owns;
  for (const Outcome& o : runs) {
    secs.push_back(o.seconds);
    peaks.push_back(double(o.peak_bytes));
    owns.push_back(double(o.peak_bytes) - double(o.base_bytes));
    s.counts_vary |= o.vertices != runs[0].vertices || o.finite_cells != runs[0].finite_cells;
  }
  s.seconds = median(secs);
  s.seconds_min = *std::min_element(secs.begin(), secs.end());
  s.seconds_max = *std::max_element(secs.begin(), secs.end());
  s.peak = median(peaks);
  s.own = median(owns);
  s.vertices = runs[0].vertices;
  s.finite_cells = runs[0].finite_cells;
  return s;
}

const Summary* find(const std::vector<Summary>& rows, Peer p, unsigned threads) {
  for (const Summary& s : rows)
    if (s.ok && s.config.peer == p && s.config.threads == threads) return &s;
  return nullptr;
}

constexpr bool have_hxt =
#ifdef PDT_BENCH_HXT
    true;
#else
    false;
#endif

}  // namespace

int main(int argc, char** argv) {
  Options o;
  ArgParser args(argv[0], "batch insertion: CGAL (batch, parallel), HXT (when built with it) and pdt, same points");
  args.count("--points", "points per distribution (default 1000000)", o.points, 1);
  args.list("--dists", "comma-separated distributions (default uniform,normal)", o.dists);
  args.counts("--threads", "comma-separated thread counts for the parallel ones (default 1,2)", o.threads, 1, 4096);
  args.count("--repeat", "runs of each configuration; the medians are reported (default 1)", o.repeat, 1);
  args.count("--seed", "the points' seed (default 1)", o.seed);
  args.text("--csv", "also write one row per configuration to this file", o.csv);
  args.real("--timeout", "seconds a configuration may run before HANG (default 600, 0 = never)", o.timeout, 0, 1e9);
  args.parse(argc, argv);
  const std::vector<pdt::Distribution> dists = distributions(o.dists);
  if (o.points > 0xFFFFFFFFull - 8) {
    std::fprintf(stderr, "%s: --points must fit HXT's 32-bit vertex indices\n", argv[0]);
    return 2;
  }

  std::printf("bench_peers: %llu points, threads", static_cast<unsigned long long>(o.points));
  for (unsigned t : o.threads) std::printf(" %u", t);
  std::printf(", %llu run(s) per configuration (%s), seed %llu\n", static_cast<unsigned long long>(o.repeat),
              o.repeat > 1 ? "medians" : "one run each", static_cast<unsigned long long>(o.seed));
  std::printf("machine: %u hardware threads (nproc %d), CPU %s\n", std::thread::hardware_concurrency(),
              affinity_cpus(), cpu_model().c_str());
  std::printf("pdt allocator: %s; oneTBB %s; CGAL %s (its Parallel_tag containers on tbbmalloc)\n",
              pdt::allocator_name(), TBB_VERSION_STRING, CGAL_VERSION_STR);
#ifdef PDT_BENCH_HXT
  std::printf("HXT: gmsh %s's (libgmsh), hxtDelaunay on an HXTMesh, OpenMP threads = delaunayThreads = T\n",
              PDT_BENCH_HXT_VERSION);
#else
  std::printf("HXT: not available (this build has no libgmsh and HXT headers: run scripts/install-hxt.sh, "
              "then re-run cmake; see cmake/PdtHxt.cmake)\n");
#endif
  std::printf("CGAL batch: Delaunay_triangulation_3<Epick>, insert(first, last); CGAL parallel: Parallel_tag TDS + "
              "Spatial_lock_grid_3 (%d cells/axis), insert(first, last) in tbb::task_arena(T)\n",
              lock_grid_cells_per_axis);
  std::printf("pdt batch: Triangulation::insert_batch; pdt engine: Engine{workers = T} in tbb::task_arena(T), "
              "insert_batch + drain\n");
  std::printf("Each configuration runs in its own process; times are the insertion only (spatial sort included).\n");

  std::vector<Config> configs{{Peer::cgal_batch, 1}};
  for (unsigned t : o.threads) configs.push_back({Peer::cgal_parallel, t});
  if (have_hxt)
    for (unsigned t : o.threads) configs.push_back({Peer::hxt, t});
  configs.push_back({Peer::pdt_batch, 1});
  for (unsigned t : o.threads) configs.push_back({Peer::pdt_engine, t});

  CsvWriter csv(o.csv,
                "dist,impl,threads,points,runs,seconds,seconds_min,seconds_max,vertices,finite_cells,peak_mib,own_mib,"
                "bytes_per_vertex,bytes_per_tet,time_vs_cgal,time_vs_hxt,peak_vs_cgal,peak_vs_hxt");
  int bad = 0, hang = 0;
  for (pdt::Distribution dist : dists) {
    const std::string dname = pdt::to_string(dist);
    const PointSet ps = generated_points(dist, o.points, o.seed);
    const pdt::Box& b = ps.box;
    std::printf("\n== %s: %zu points (box [%g,%g]x[%g,%g]x[%g,%g]) ==\n", dname.c_str(), ps.points.size(), b.lo.x,
                b.hi.x, b.lo.y, b.hi.y, b.lo.z, b.hi.z);
    std::fflush(stdout);

    std::vector<std::vector<Outcome>> runs(configs.size());
    std::vector<std::string> errors(configs.size());
    for (std::uint64_t round = 0; round < o.repeat; ++round)
      for (std::size_t i = 0; i < configs.size(); ++i) {
        if (!errors[i].empty()) continue;
        progress("%s: %s (run %llu/%llu)...\n", dname.c_str(), configs[i].label().c_str(),
                 static_cast<unsigned long long>(round + 1), static_cast<unsigned long long>(o.repeat));
        Outcome out;
        const ChildStatus st = in_child([&] { return run_config(configs[i], ps, o.timeout); }, out);
        if (st.ok)
          runs[i].push_back(out);
        else
          errors[i] = st.error;
        if (st.exit_code == 3) hang = 1;  // its watchdog printed HANG
      }

    std::vector<Summary> rows;
    for (std::size_t i = 0; i < configs.size(); ++i) rows.push_back(summarise(configs[i], runs[i], errors[i]));
    const Summary* ref = find(rows, Peer::cgal_batch, 1);

    // The peer a row is compared with: CGAL / HXT at the same thread count
    // (CGAL batch and HXT on 1 thread for pdt batch; CGAL batch for CGAL parallel).
    auto cgal_of = [&](const Summary& s) -> const Summary* {
      if (s.config.peer == Peer::pdt_batch || s.config.peer == Peer::cgal_parallel) return ref;
      if (s.config.peer == Peer::pdt_engine || s.config.peer == Peer::hxt)
        return find(rows, Peer::cgal_parallel, s.config.threads);
      return nullptr;
    };
    auto hxt_of = [&](const Summary& s) -> const Summary* {
      if (s.config.peer == Peer::pdt_batch || s.config.peer == Peer::pdt_engine)
        return find(rows, Peer::hxt, s.config.threads);
      return nullptr;
    };
    auto ratio = [](const Summary* den, double num, double Summary::*field) {
      return den ? fmt_ratio(num, den->*field) : std::string("-");
    };

    std::printf("%-18s %9s %9s %9s %9s %12s %10s %9s %9s %9s %9s %9s\n", "", "time (s)", "min", "max", "vs CGAL",
                "finite tets", "peak MiB", "own MiB", "B/vertex", "B/tet", "vs HXT", "peak/HXT");
    for (const Summary& s : rows) {
      if (!s.ok) {
        std::printf("%-18s FAILED: %s\n", s.config.label().c_str(), s.error.c_str());
        ++bad;
        continue;
      }
      const double vtx = double(s.vertices), tets = double(s.finite_cells);
      const Summary* c = cgal_of(s);
      const Summary* h = hxt_of(s);
      const std::string vs_cgal = ratio(c, s.seconds, &Summary::seconds);
      const std::string vs_hxt = ratio(h, s.seconds, &Summary::seconds);
      const std::string peak_cgal = ratio(c, s.peak, &Summary::peak);
      const std::string peak_hxt = ratio(h, s.peak, &Summary::peak);
      std::printf("%-18s %9.3f %9.3f %9.3f %9s %12s %10.1f %9.1f %9.1f %9.1f %9s %9s\n", s.config.label().c_str(),
                  s.seconds, s.seconds_min, s.seconds_max, vs_cgal.c_str(), fmt_u(s.finite_cells).c_str(),
                  mib(s.peak), mib(s.own), vtx > 0 ? s.own / vtx : 0.0, tets > 0 ? s.own / tets : 0.0,
                  vs_hxt.c_str(), peak_hxt.c_str());
      csv.row({dname, peer_key(s.config.peer), std::to_string(s.config.threads), std::to_string(o.points),
               std::to_string(runs[&s - rows.data()].size()), fmt("%.4f", s.seconds), fmt("%.4f", s.seconds_min),
               fmt("%.4f", s.seconds_max), std::to_string(s.vertices), std::to_string(s.finite_cells),
               fmt("%.1f", mib(s.peak)), fmt("%.1f", mib(s.own)), fmt("%.1f", vtx > 0 ? s.own / vtx : 0.0),
               fmt("%.1f", tets > 0 ? s.own / tets : 0.0), vs_cgal, vs_hxt, peak_cgal, peak_hxt});
      if (ref && (s.vertices != ref->vertices || s.finite_cells != ref->finite_cells)) {
        std::printf("  MISMATCH: %s has %llu vertices and %llu finite tetrahedra, CGAL batch %llu and %llu\n",
                    s.config.label().c_str(), static_cast<unsigned long long>(s.vertices),
                    static_cast<unsigned long long>(s.finite_cells), static_cast<unsigned long long>(ref->vertices),
                    static_cast<unsigned long long>(ref->finite_cells));
        ++bad;
      }
      if (s.counts_vary) {
        std::printf("  MISMATCH: %s's runs disagree on the counts\n", s.config.label().c_str());
        ++bad;
      }
    }
    if (!ref) {
      std::printf("  MISMATCH: no CGAL batch reference to check the counts against\n");
      ++bad;
    }

    std::printf("\n%-44s %9s %9s\n", "pdt / peer (below 1: pdt faster, smaller)", "time", "peak mem");
    auto pair_line = [&](Peer p, unsigned tp, Peer q, unsigned tq) {
      const Summary* a = find(rows, p, tp);
      const Summary* c = find(rows, q, tq);
      if (!a || !c) return;
      const std::string name = a->config.label() + " / " + c->config.label();
      std::printf("%-44s %9s %9s\n", name.c_str(), fmt_ratio(a->seconds, c->seconds).c_str(),
                  fmt_ratio(a->peak, c->peak).c_str());
    };
    pair_line(Peer::pdt_batch, 1, Peer::cgal_batch, 1);
    for (unsigned t : o.threads) pair_line(Peer::pdt_engine, t, Peer::cgal_parallel, t);
    pair_line(Peer::pdt_batch, 1, Peer::hxt, 1);
    for (unsigned t : o.threads) pair_line(Peer::pdt_engine, t, Peer::hxt, t);
    std::fflush(stdout);
  }
  std::printf("\n'vs CGAL': this time / CGAL's at the same thread count (pdt batch and CGAL parallel: / CGAL batch); "
              "'vs HXT', 'peak/HXT': pdt / HXT at the same thread count (pdt batch: HXT on 1 thread). "
              "'own MiB': peak minus the process's resident memory at its start (program and points), "
              "per vertex and per finite tetrahedron in B/vertex, B/tet.\n");
  if (bad) std::printf("%d problem(s): see FAILED / MISMATCH above\n", bad);
  return hang ? 3 : bad ? 1 : 0;
}
