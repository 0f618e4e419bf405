// SPDX-License-Identifier: MIT
// bench_sequential: pdt's sequential insertion and removal against CGAL's
// Delaunay_triangulation_3 (Epick, Fast_location), one point at a time, same
// points, same order, same run.
//
//   bench_sequential [--points N] [--dists uniform,normal,line] [--remove-fraction F] [--seed S]
//                    [--inputs FILE,FILE...] [--repeat K]
//
// Per distribution: N points from pdt::generate, inserted one at a time in the
// generated (random) order with no spatial sort; per input file (--inputs,
// any format pdt::read_points reads, e.g. the scans in ../shared/data): its
// distinct points in a random order (seeded), which is how a refiner's
// points arrive, not the scanner's order. Then the first F*N insertions
// are undone one at a time. pdt runs first and is freed before CGAL runs, so
// the resident-memory deltas (VmRSS from /proc/self/status) are measured
// separately. The two final triangulations must have the same number of finite
// cells (MISMATCH is printed otherwise).
// Then batch mode: Triangulation::insert_batch(all) against CGAL's
// insert(first, last), both spatially sorting the batch inside the timing.
// --repeat K runs each distribution K rounds (pdt and CGAL alternate within a
// round, so a slow spell of a shared machine hits both) and prints medians,
// with each ratio's range over the rounds.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "common/bench_util.hpp"
#include "common/cgal_runners.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"
#include "support/sys_info.hpp"

namespace {

using namespace pdt_bench;
using pdt::support::Stopwatch;

double rss() { return static_cast<double>(pdt::support::current_rss_bytes()); }

struct Row {
  std::string dist;
  std::size_t n = 0, removed = 0;
  double pdt_insert = 0, pdt_remove = 0;
  double created_per_insert = 0, touched_per_remove = 0, walk_per_insert = 0;
  double pdt_bytes_per_tet = 0;
  double pdt_rss_insert = 0, pdt_rss_remove = 0;
  std::size_t pdt_cells_after_insert = 0, pdt_finite = 0, pdt_vertices = 0;
  CgalRun cgal;
  // Batch mode: pdt insert_batch vs CGAL insert(first, last), both spatially sorted inside.
  double pdt_batch = 0, cgal_batch = 0;
  std::size_t pdt_batch_cells = 0, cgal_batch_cells = 0;
};

Row run_one(const std::string& name, const std::vector<pdt::Point3>& pts, double remove_fraction) {
  Row row;
  row.dist = name;
  row.n = pts.size();
  const std::size_t n_remove = static_cast<std::size_t>(remove_fraction * double(pts.size()));
  row.removed = n_remove;

  // ---- pdt --------------------------------------------------------------------
  {
    std::vector<pdt::VertexId> ids(pts.size());
    settle();
    const double rss0 = rss();
    pdt::Triangulation t;
    Stopwatch sw;
    for (std::size_t k = 0; k < pts.size(); ++k) ids[k] = t.insert(pts[k]).vertex;
    row.pdt_insert = sw.seconds();
    const double rss1 = rss();
    row.pdt_rss_insert = rss1 - rss0;
    row.pdt_cells_after_insert = t.number_of_cells();
    row.pdt_bytes_per_tet = t.number_of_cells() ? double(t.memory_bytes()) / double(t.number_of_cells()) : 0;
    const auto st0 = t.stats();

    sw.restart();
    for (std::size_t k = 0; k < n_remove; ++k) t.remove(ids[k]);
    row.pdt_remove = sw.seconds();
    row.pdt_rss_remove = rss() - rss1;

    const auto& st = t.stats();
    row.created_per_insert = st0.insertions ? double(st0.cells_created_by_insert) / double(st0.insertions) : 0;
    row.walk_per_insert = st0.insertions ? double(st0.walk_steps) / double(st0.insertions) : 0;
    const std::uint64_t removals = st.removals - st0.removals;
    row.touched_per_remove =
        removals ? double(st.cells_touched_by_remove - st0.cells_touched_by_remove) / double(removals) : 0;
    row.pdt_finite = t.number_of_finite_cells();
    row.pdt_vertices = t.number_of_vertices();
  }

  // ---- CGAL -------------------------------------------------------------------
  row.cgal = cgal_sequential(pts, last_removals(pts, n_remove));

  // ---- batch mode -----------------------------------------------------------------
  {
    settle();
    pdt::Triangulation t;
    Stopwatch sw;
    t.insert_batch(pts);
    row.pdt_batch = sw.seconds();
    row.pdt_batch_cells = t.number_of_cells();
  }
  row.cgal_batch = cgal_batch_insert(pts, &row.cgal_batch_cells);
  return row;
}

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

struct Range {
  double lo = 0, hi = 0;
};

// Medians of the times over the rounds (everything else from the first);
// the ranges of the per-round ratios in *ins, *rem, *batch.
Row merge_rounds(const std::vector<Row>& rounds, Range* ins, Range* rem, Range* batch) {
  Row r = rounds.front();
  auto med = [&](auto get) {
    std::vector<double> v;
    for (const Row& x : rounds) v.push_back(get(x));
    return median_of(v);
  };
  auto range = [&](auto num, auto den) {
    Range g{1e300, 0};
    for (const Row& x : rounds) {
      const double q = den(x) > 0 ? num(x) / den(x) : 0;
      g.lo = std::min(g.lo, q);
      g.hi = std::max(g.hi, q);
    }
    return g;
  };
  r.pdt_insert = med([](const Row& x) { return x.pdt_insert; });
  r.pdt_remove = med([](const Row& x) { return x.pdt_remove; });
  r.pdt_batch = med([](const Row& x) { return x.pdt_batch; });
  r.cgal.insert_seconds = med([](const Row& x) { return x.cgal.insert_seconds; });
  r.cgal.remove_seconds = med([](const Row& x) { return x.cgal.remove_seconds; });
  r.cgal_batch = med([](const Row& x) { return x.cgal_batch; });
  *ins = range([](const Row& x) { return x.pdt_insert; }, [](const Row& x) { return x.cgal.insert_seconds; });
  *rem = range([](const Row& x) { return x.pdt_remove; }, [](const Row& x) { return x.cgal.remove_seconds; });
  *batch = range([](const Row& x) { return x.pdt_batch; }, [](const Row& x) { return x.cgal_batch; });
  return r;
}

bool same_shapes(const Row& r) {
  const CgalRun& c = r.cgal;
  return r.pdt_finite == c.shape.finite_cells && r.pdt_vertices == c.shape.vertices &&
         r.pdt_cells_after_insert == c.cells_after_insert_all && r.pdt_batch_cells == r.cgal_batch_cells;
}

}  // namespace

int main(int argc, char** argv) {
  std::uint64_t points = 1000000, seed = 1, repeat = 1;
  std::vector<std::string> dist_names{"uniform", "normal", "line"}, inputs;
  double remove_fraction = 0.1;
  ArgParser args(argv[0], "pdt's sequential kernel against CGAL's Delaunay_triangulation_3, one point at a time, "
                          "then in batch mode");
  args.count("--points", "points per distribution (default 1000000)", points, 1);
  args.list("--dists", "comma-separated distributions (default uniform,normal,line)", dist_names);
  args.real("--remove-fraction", "fraction of the insertions undone afterwards, first inserted first (default 0.1)",
            remove_fraction, 0, 1);
  args.count("--seed", "generator seed (default 1)", seed);
  args.list("--inputs", "comma-separated point files, run after the distributions (their distinct points, shuffled)",
            inputs);
  args.count("--repeat", "rounds per distribution, pdt and CGAL alternating; medians and ratio ranges (default 1)",
             repeat, 1);
  args.parse(argc, argv);
  const std::vector<pdt::Distribution> dists = distributions(dist_names);
  // Every input read before anything runs: a bad file fails at once.
  std::vector<std::pair<std::string, std::vector<pdt::Point3>>> input_sets;
  for (const std::string& path : inputs) {
    std::vector<pdt::Point3> pts;
    try {
      pts = pdt::read_points(path);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bench_sequential: --inputs: %s\n", e.what());
      return 2;
    }
    // Distinct points only: CGAL's remove(vh) drops a vertex whatever its
    // multiplicity, pdt's remove lowers the multiplicity first.
    auto key = [](const pdt::Point3& p) { return std::tuple(p.x, p.y, p.z); };
    std::sort(pts.begin(), pts.end(), [&](const pdt::Point3& a, const pdt::Point3& b) { return key(a) < key(b); });
    pts.erase(std::unique(pts.begin(), pts.end(), [&](const pdt::Point3& a, const pdt::Point3& b) { return key(a) == key(b); }),
              pts.end());
    std::shuffle(pts.begin(), pts.end(), std::mt19937_64(seed));
    input_sets.emplace_back(std::filesystem::path(path).filename().string(), std::move(pts));
  }

  std::printf("bench_sequential: %llu points, remove fraction %g, seed %llu; one point at a time, no spatial sort\n",
              static_cast<unsigned long long>(points), remove_fraction, static_cast<unsigned long long>(seed));
  std::printf("CGAL: Delaunay_triangulation_3<Epick, Default, Fast_location>, insert(p) / remove(vh)\n");
  if (repeat > 1)
    std::printf("%llu rounds per distribution: times are medians; the ratios' ranges over the rounds follow the "
                "tables\n",
                static_cast<unsigned long long>(repeat));
  std::printf("\n");
  std::printf("%-8s %9s | %9s %9s %6s | %8s %9s %9s %6s | %8s %8s %6s | %8s %9s %9s %9s %9s | %s\n", "dist",
              "N", "pdt ins s", "CGAL ins", "ratio", "removed", "pdt rem s", "CGAL rem", "ratio", "created/",
              "touched/", "walk/", "pdt B/", "pdt RSS", "pdt RSS", "CGAL RSS", "CGAL RSS", "finite cells");
  std::printf("%-8s %9s | %9s %9s %6s | %8s %9s %9s %6s | %8s %8s %6s | %8s %9s %9s %9s %9s | %s\n", "", "", "",
              "s", "", "", "", "s", "", "insert", "remove", "insert", "tet", "ins MiB", "rem MiB", "ins MiB", "rem MiB",
              "pdt / CGAL");
  int mismatches = 0;
  std::vector<Row> rows;
  std::vector<Range> ins_ranges, rem_ranges, batch_ranges;
  std::vector<std::pair<std::string, std::vector<pdt::Point3>>> sets;
  for (pdt::Distribution d : dists) sets.emplace_back(pdt::to_string(d), std::vector<pdt::Point3>{});
  for (auto& set : input_sets) sets.push_back(std::move(set));
  for (std::size_t i = 0; i < sets.size(); ++i) {
    // A distribution's points are generated only when its turn comes.
    if (i < dists.size()) sets[i].second = generated_points(dists[i], points, seed).points;
    std::vector<Row> rounds;
    bool same = true;
    for (std::uint64_t k = 0; k < repeat; ++k) {
      rounds.push_back(run_one(sets[i].first, sets[i].second, remove_fraction));
      same = same && same_shapes(rounds.back());
    }
    sets[i].second = {};
    Range ins, rem, batch;
    const Row& r = rows.emplace_back(merge_rounds(rounds, &ins, &rem, &batch));
    ins_ranges.push_back(ins);
    rem_ranges.push_back(rem);
    batch_ranges.push_back(batch);
    const CgalRun& c = r.cgal;
    mismatches += !same;
    std::printf(
        "%-8s %9zu | %9.3f %9.3f %6.2f | %8zu %9.3f %9.3f %6.2f | %8.2f %8.2f %6.2f | %8.1f %9.1f %9.1f %9.1f %9.1f | "
        "%zu / %zu%s\n",
        r.dist.c_str(), r.n, r.pdt_insert, c.insert_seconds,
        c.insert_seconds > 0 ? r.pdt_insert / c.insert_seconds : 0.0, r.removed, r.pdt_remove, c.remove_seconds,
        c.remove_seconds > 0 ? r.pdt_remove / c.remove_seconds : 0.0, r.created_per_insert, r.touched_per_remove,
        r.walk_per_insert,
        r.pdt_bytes_per_tet, mib(r.pdt_rss_insert), mib(r.pdt_rss_remove), mib(c.rss_insert), mib(c.rss_remove),
        r.pdt_finite, c.shape.finite_cells, same ? "" : "  MISMATCH");
    if (!same)
      std::printf("  MISMATCH detail: cells after insertion pdt %zu CGAL %zu; vertices after removal pdt %zu CGAL %zu\n",
                  r.pdt_cells_after_insert, c.cells_after_insert_all, r.pdt_vertices, c.shape.vertices);
    std::fflush(stdout);
  }
  std::printf("\nBatch mode: pdt Triangulation::insert_batch(all) vs CGAL insert(first, last); both spatially sort\n");
  std::printf("%-8s %9s | %11s %11s %6s | %s\n", "dist", "N", "pdt batch s", "CGAL batch", "ratio", "cells pdt / CGAL");
  for (const Row& r : rows)
    std::printf("%-8s %9zu | %11.3f %11.3f %6.2f | %zu / %zu%s\n", r.dist.c_str(), r.n, r.pdt_batch, r.cgal_batch,
                r.cgal_batch > 0 ? r.pdt_batch / r.cgal_batch : 0.0, r.pdt_batch_cells, r.cgal_batch_cells,
                r.pdt_batch_cells == r.cgal_batch_cells ? "" : "  MISMATCH");
  if (repeat > 1) {
    std::printf("\nRatio ranges over the %llu rounds (pdt / CGAL, each round's own)\n",
                static_cast<unsigned long long>(repeat));
    std::printf("%-8s | %13s | %13s | %13s\n", "dist", "insert", "remove", "batch");
    for (std::size_t i = 0; i < rows.size(); ++i)
      std::printf("%-8s | %5.2f - %5.2f | %5.2f - %5.2f | %5.2f - %5.2f\n", rows[i].dist.c_str(), ins_ranges[i].lo,
                  ins_ranges[i].hi, rem_ranges[i].lo, rem_ranges[i].hi, batch_ranges[i].lo, batch_ranges[i].hi);
  }
  if (mismatches) std::printf("\n%d distribution(s) with MISMATCH\n", mismatches);
  return mismatches ? 1 : 0;
}
