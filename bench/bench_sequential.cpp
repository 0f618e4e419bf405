// bench_sequential: pdt's sequential insertion and removal against CGAL's
// Delaunay_triangulation_3 (Epick, Fast_location), one point at a time, same
// points, same order, same run.
//
//   bench_sequential [--points N] [--dists uniform,normal,line] [--remove-fraction F] [--seed S]
//
// Per distribution: N points from pdt::generate, inserted one at a time in the
// generated (random) order with no spatial sort; then the first F*N insertions
// are undone one at a time. pdt runs first and is freed before CGAL runs, so
// the resident-memory deltas (VmRSS from /proc/self/status) are measured
// separately. The two final triangulations must have the same number of finite
// cells (MISMATCH is printed otherwise).
// Then batch mode: Triangulation::insert_batch(all) against CGAL's
// insert(first, last), both spatially sorting the batch inside the timing.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <malloc.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/triangulation.hpp"
#include "sys_info.hpp"

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using CgalDT = CGAL::Delaunay_triangulation_3<K, CGAL::Default, CGAL::Fast_location>;

std::size_t rss_bytes() { return static_cast<std::size_t>(pdt::detail::current_rss_bytes()); }

// Returns freed heap to the OS so RSS deltas of the next phase start clean.
std::size_t settled_rss() {
  ::malloc_trim(0);
  return rss_bytes();
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double mib(double bytes) { return bytes / (1024.0 * 1024.0); }
double signed_delta(std::size_t after, std::size_t before) { return double(after) - double(before); }

struct PointHash {
  std::size_t operator()(const pdt::Point3& p) const {
    std::size_t h = std::hash<double>()(p.x + 0.0);
    h ^= std::hash<double>()(p.y + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
    h ^= std::hash<double>()(p.z + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
    return h;
  }
};

struct Options {
  std::uint64_t points = 1000000;
  std::vector<std::string> dists{"uniform", "normal", "line"};
  double remove_fraction = 0.1;
  std::uint64_t seed = 1;
};

[[noreturn]] void usage(const char* prog, int code) {
  std::fprintf(code ? stderr : stdout,
               "usage: %s [--points N] [--dists uniform,normal,line,grid,sphere] [--remove-fraction F] [--seed S]\n"
               "  --points N           points per distribution (default 1000000)\n"
               "  --dists LIST         comma-separated distributions (default uniform,normal,line)\n"
               "  --remove-fraction F  fraction of the insertions undone afterwards, first inserted first "
               "(default 0.1)\n"
               "  --seed S             generator seed (default 1)\n",
               prog);
  std::exit(code);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s: %s needs a value\n", argv[0], a.c_str());
        usage(argv[0], 2);
      }
      return argv[++i];
    };
    try {
      if (a == "--points") {
        std::string v = value();
        std::size_t pos = 0;
        o.points = std::stoull(v, &pos);
        if (pos != v.size() || o.points == 0) throw std::invalid_argument(v);
      } else if (a == "--dists") {
        o.dists.clear();
        std::stringstream ss(value());
        std::string d;
        while (std::getline(ss, d, ','))
          if (!d.empty()) o.dists.push_back(d);
        if (o.dists.empty()) throw std::invalid_argument("empty list");
      } else if (a == "--remove-fraction") {
        std::string v = value();
        std::size_t pos = 0;
        o.remove_fraction = std::stod(v, &pos);
        if (pos != v.size() || !(o.remove_fraction >= 0 && o.remove_fraction <= 1)) throw std::invalid_argument(v);
      } else if (a == "--seed") {
        std::string v = value();
        std::size_t pos = 0;
        o.seed = std::stoull(v, &pos);
        if (pos != v.size()) throw std::invalid_argument(v);
      } else if (a == "--help" || a == "-h") {
        usage(argv[0], 0);
      } else {
        std::fprintf(stderr, "%s: unknown option %s\n", argv[0], a.c_str());
        usage(argv[0], 2);
      }
    } catch (const std::logic_error&) {
      std::fprintf(stderr, "%s: bad value for %s\n", argv[0], a.c_str());
      usage(argv[0], 2);
    }
  }
  return o;
}

struct Row {
  std::string dist;
  std::size_t n = 0, removed = 0;
  double pdt_insert = 0, cgal_insert = 0, pdt_remove = 0, cgal_remove = 0;
  double created_per_insert = 0, touched_per_remove = 0;
  double pdt_bytes_per_tet = 0;
  double pdt_rss_insert = 0, pdt_rss_remove = 0, cgal_rss_insert = 0, cgal_rss_remove = 0;
  std::size_t pdt_cells_after_insert = 0, cgal_cells_after_insert = 0;
  std::size_t pdt_finite = 0, cgal_finite = 0;
  std::size_t pdt_vertices = 0, cgal_vertices = 0;
  // Batch mode: pdt insert_batch vs CGAL insert(first, last), both spatially sorted inside.
  double pdt_batch = 0, cgal_batch = 0;
  std::size_t pdt_batch_cells = 0, cgal_batch_cells = 0;
};

Row run_one(const Options& o, pdt::Distribution dist) {
  Row row;
  row.dist = pdt::to_string(dist);
  std::vector<pdt::Point3> pts;
  {
    pdt::GenerateOptions g;
    g.dist = dist;
    g.points = o.points;
    g.seed = o.seed;
    pdt::OpStream s = pdt::generate(g);
    pts.reserve(s.ops.size());
    for (const auto& op : s.ops)
      if (op.kind == pdt::Operation::Kind::insert) pts.push_back(op.point);
  }
  row.n = pts.size();
  const std::size_t n_remove = static_cast<std::size_t>(o.remove_fraction * double(pts.size()));
  row.removed = n_remove;

  // Which of the first n_remove insertions make a vertex disappear (the last
  // undone insertion of its point): CGAL has no multiplicity, pdt does.
  std::vector<char> cgal_removes(n_remove, 0);
  {
    std::unordered_map<pdt::Point3, std::uint32_t, PointHash> count;
    count.reserve(pts.size() * 2);
    for (const auto& p : pts) ++count[p];
    for (std::size_t k = 0; k < n_remove; ++k) cgal_removes[k] = --count[pts[k]] == 0;
  }

  // ---- pdt --------------------------------------------------------------------
  {
    std::vector<pdt::VertexId> ids(pts.size());
    const std::size_t rss0 = settled_rss();
    pdt::Triangulation t;
    auto t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < pts.size(); ++k) ids[k] = t.insert(pts[k]).vertex;
    row.pdt_insert = seconds_since(t0);
    const std::size_t rss1 = rss_bytes();
    row.pdt_rss_insert = signed_delta(rss1, rss0);
    row.pdt_cells_after_insert = t.number_of_cells();
    row.pdt_bytes_per_tet = t.number_of_cells() ? double(t.memory_bytes()) / double(t.number_of_cells()) : 0;
    const auto st0 = t.stats();

    t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < n_remove; ++k) t.remove(ids[k]);
    row.pdt_remove = seconds_since(t0);
    row.pdt_rss_remove = signed_delta(rss_bytes(), rss1);

    const auto& st = t.stats();
    row.created_per_insert = st0.insertions ? double(st0.cells_created_by_insert) / double(st0.insertions) : 0;
    const std::uint64_t removals = st.removals - st0.removals;
    row.touched_per_remove =
        removals ? double(st.cells_touched_by_remove - st0.cells_touched_by_remove) / double(removals) : 0;
    row.pdt_finite = t.number_of_finite_cells();
    row.pdt_vertices = t.number_of_vertices();
  }

  // ---- CGAL -------------------------------------------------------------------
  {
    std::vector<CgalDT::Vertex_handle> vh(n_remove);
    std::vector<K::Point_3> cpts;
    cpts.reserve(pts.size());
    for (const auto& p : pts) cpts.emplace_back(p.x, p.y, p.z);
    const std::size_t rss0 = settled_rss();
    CgalDT dt;
    auto t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < cpts.size(); ++k) {
      CgalDT::Vertex_handle v = dt.insert(cpts[k]);
      if (k < n_remove) vh[k] = v;
    }
    row.cgal_insert = seconds_since(t0);
    const std::size_t rss1 = rss_bytes();
    row.cgal_rss_insert = signed_delta(rss1, rss0);
    row.cgal_cells_after_insert = dt.number_of_cells();

    t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < n_remove; ++k)
      if (cgal_removes[k]) dt.remove(vh[k]);
    row.cgal_remove = seconds_since(t0);
    row.cgal_rss_remove = signed_delta(rss_bytes(), rss1);
    row.cgal_finite = dt.number_of_finite_cells();
    row.cgal_vertices = dt.number_of_vertices();
  }

  // ---- batch mode -----------------------------------------------------------------
  {
    settled_rss();
    pdt::Triangulation t;
    auto t0 = std::chrono::steady_clock::now();
    t.insert_batch(pts);
    row.pdt_batch = seconds_since(t0);
    row.pdt_batch_cells = t.number_of_cells();
  }
  {
    std::vector<K::Point_3> cpts;
    cpts.reserve(pts.size());
    for (const auto& p : pts) cpts.emplace_back(p.x, p.y, p.z);
    settled_rss();
    CgalDT dt;
    auto t0 = std::chrono::steady_clock::now();
    dt.insert(cpts.begin(), cpts.end());
    row.cgal_batch = seconds_since(t0);
    row.cgal_batch_cells = dt.number_of_cells();
  }
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  std::vector<pdt::Distribution> dists;
  try {
    for (const auto& d : o.dists) dists.push_back(pdt::parse_distribution(d));
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 2;
  }
  std::printf("bench_sequential: %llu points, remove fraction %g, seed %llu; one point at a time, no spatial sort\n",
              static_cast<unsigned long long>(o.points), o.remove_fraction,
              static_cast<unsigned long long>(o.seed));
  std::printf("CGAL: Delaunay_triangulation_3<Epick, Default, Fast_location>, insert(p) / remove(vh)\n\n");
  std::printf("%-8s %9s | %9s %9s %6s | %8s %9s %9s %6s | %8s %8s | %8s %9s %9s %9s %9s | %s\n", "dist", "N",
              "pdt ins s", "CGAL ins", "ratio", "removed", "pdt rem s", "CGAL rem", "ratio", "created/", "touched/",
              "pdt B/", "pdt RSS", "pdt RSS", "CGAL RSS", "CGAL RSS", "finite cells");
  std::printf("%-8s %9s | %9s %9s %6s | %8s %9s %9s %6s | %8s %8s | %8s %9s %9s %9s %9s | %s\n", "", "", "", "s",
              "", "", "", "s", "", "insert", "remove", "tet", "ins MiB", "rem MiB", "ins MiB", "rem MiB",
              "pdt / CGAL");
  int mismatches = 0;
  std::vector<Row> rows;
  for (pdt::Distribution d : dists) {
    const Row& r = rows.emplace_back(run_one(o, d));
    const bool same = r.pdt_finite == r.cgal_finite && r.pdt_vertices == r.cgal_vertices &&
                      r.pdt_cells_after_insert == r.cgal_cells_after_insert && r.pdt_batch_cells == r.cgal_batch_cells;
    mismatches += !same;
    std::printf(
        "%-8s %9zu | %9.3f %9.3f %6.2f | %8zu %9.3f %9.3f %6.2f | %8.2f %8.2f | %8.1f %9.1f %9.1f %9.1f %9.1f | "
        "%zu / %zu%s\n",
        r.dist.c_str(), r.n, r.pdt_insert, r.cgal_insert, r.cgal_insert > 0 ? r.pdt_insert / r.cgal_insert : 0.0,
        r.removed, r.pdt_remove, r.cgal_remove, r.cgal_remove > 0 ? r.pdt_remove / r.cgal_remove : 0.0,
        r.created_per_insert, r.touched_per_remove, r.pdt_bytes_per_tet, mib(r.pdt_rss_insert),
        mib(r.pdt_rss_remove), mib(r.cgal_rss_insert), mib(r.cgal_rss_remove), r.pdt_finite, r.cgal_finite,
        same ? "" : "  MISMATCH");
    if (!same)
      std::printf("  MISMATCH detail: cells after insertion pdt %zu CGAL %zu; vertices after removal pdt %zu CGAL %zu\n",
                  r.pdt_cells_after_insert, r.cgal_cells_after_insert, r.pdt_vertices, r.cgal_vertices);
    std::fflush(stdout);
  }
  std::printf("\nBatch mode: pdt Triangulation::insert_batch(all) vs CGAL insert(first, last); both spatially sort\n");
  std::printf("%-8s %9s | %11s %11s %6s | %s\n", "dist", "N", "pdt batch s", "CGAL batch", "ratio", "cells pdt / CGAL");
  for (const Row& r : rows)
    std::printf("%-8s %9zu | %11.3f %11.3f %6.2f | %zu / %zu%s\n", r.dist.c_str(), r.n, r.pdt_batch, r.cgal_batch,
                r.cgal_batch > 0 ? r.pdt_batch / r.cgal_batch : 0.0, r.pdt_batch_cells, r.cgal_batch_cells,
                r.pdt_batch_cells == r.cgal_batch_cells ? "" : "  MISMATCH");
  if (mismatches) std::printf("\n%d distribution(s) with MISMATCH\n", mismatches);
  return mismatches ? 1 : 0;
}
