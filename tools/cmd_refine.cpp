// SPDX-License-Identifier: MIT
// pdt refine: meshes a domain with the parallel Delaunay refiner of
// tools/refine (written on pdt's public API only), then reports the mesh.
#include <cstdio>
#include <optional>
#include <string>
#include <thread>
#include <unistd.h>
#include <unordered_map>
#include <vector>

#include "cli.hpp"
#include "pdt/pdt.hpp"
#include "refine/quality.hpp"
#include "refine/refiner.hpp"
#include "support/cli_text.hpp"
#include "support/sys_info.hpp"

namespace pdt_cli {

using pdt::support::ends_with_nocase;
using pdt::support::format_count;
using pdt::support::format_megabytes;
using pdt::support::format_seconds;

const char* const refine_usage =
    "usage: pdt refine --domain D --size H [options]\n"
    "\n"
    "Meshes domain D with tetrahedra: Delaunay refinement on the parallel engine.\n"
    "Every tetrahedron whose circumcentre is inside D ends with circumradius <= H\n"
    "and radius-edge ratio <= B, but for a thin protected layer along the surface\n"
    "(circumcentres within H/4 of a surface sample); points sampled on D's surface\n"
    "protect it, and vertices that land too close to one (within 3H/4) are removed.\n"
    "\n"
    "options:\n"
    "  --domain D      sphere (radius 1), torus (radii 1 and 0.4, axis z) or gyroid (a gyroid\n"
    "                  slab in [-1, 1]^3: non-convex, multiply connected)\n"
    "  --size H        the circumradius bound (and about the surface samples' spacing)\n"
    "  --ratio B       the radius-edge bound, at least 2 (default 2)\n"
    "  --threads N     the engine's workers (default, and 0: one per core)\n"
    "  --seed S        which surface samples are kept, and the jitter of the starting lattice\n"
    "                  (default 1)\n"
    "  --budget N      stop after N points (default 20,000,000); reported when hit, and a surface\n"
    "                  whose samples and the box's 8 corners exceed it is refused before anything\n"
    "                  is inserted\n"
    "  --out FILE      FILE.vtu: the tetrahedra inside D (centroid inside), with per-cell\n"
    "                  radius_edge_ratio, min_dihedral_angle and domain_label;\n"
    "                  FILE.node: the whole triangulation (TetGen .node + .ele)\n"
    "  --trace FILE    write the operations carried out as a stream (.ops text, .opsb binary), which\n"
    "                  `pdt run FILE --threads N` replays\n"
    "  --validate      check every invariant of the final triangulation\n"
    "Exit status: 0 done, 1 a bound is missed, the budget stopped it unfinished, or validation\n"
    "failed, 2 error.\n";

namespace {

// The tetrahedra inside the domain, with their quality as cell data.
void write_inside_vtu(const std::string& path, const pdt::Triangulation& t, const pdt_refine::Domain& d) {
  pdt::Mesh m;
  std::unordered_map<pdt::VertexId, std::uint32_t> node;
  std::vector<pdt::CellField> fields{{"radius_edge_ratio", {}}, {"min_dihedral_angle", {}}, {"domain_label", {}}};
  for (pdt::CellId c = 0; c < t.cell_id_bound(); ++c) {
    if (!t.is_finite_cell(c)) continue;
    std::array<pdt::Point3, 4> p;
    for (int i = 0; i < 4; ++i) p[i] = t.point(t.cell_vertex(c, i));
    const pdt::Point3 centroid{(p[0].x + p[1].x + p[2].x + p[3].x) / 4, (p[0].y + p[1].y + p[2].y + p[3].y) / 4,
                               (p[0].z + p[1].z + p[2].z + p[3].z) / 4};
    if (!(d.f(centroid) < 0)) continue;
    std::array<std::uint32_t, 4> tet{};
    for (int i = 0; i < 4; ++i) {
      const pdt::VertexId v = t.cell_vertex(c, i);
      auto [it, fresh] = node.emplace(v, static_cast<std::uint32_t>(m.points.size()));
      if (fresh) m.points.push_back(p[i]);
      tet[i] = it->second;
    }
    m.tets.push_back(tet);
    fields[0].values.push_back(pdt_refine::shape(p).radius_edge);
    fields[1].values.push_back(pdt_refine::min_dihedral_degrees(p));
    fields[2].values.push_back(d.label);
  }
  pdt::write_vtu(path, m, pdt::VtuEncoding::zlib, fields);
}

}  // namespace

int cmd_refine(Args args) {
  std::optional<std::string> domain_name, out, trace;
  std::optional<double> size;
  double ratio = 2;
  unsigned workers = std::max(1u, std::thread::hardware_concurrency());
  std::uint64_t seed = 1, budget = 20000000;
  bool validate = false;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(refine_usage, stdout);
      return 0;
    }
    if (args.option("--domain", true)) {
      domain_name = args.value();
    } else if (args.option("--size", true)) {
      size = parse_real_option(args, "--size", args.value());
    } else if (args.option("--ratio", true)) {
      ratio = parse_real_option(args, "--ratio", args.value());
    } else if (args.option("--threads", true)) {
      workers = parse_workers_option(args, args.value());
    } else if (args.option("--seed", true)) {
      seed = parse_count_option(args, "--seed", args.value());
    } else if (args.option("--budget", true)) {
      budget = parse_count_option(args, "--budget", args.value());
    } else if (args.option("--out", true)) {
      out = args.value();
    } else if (args.option("--trace", true)) {
      trace = args.value();
    } else if (args.option("--validate", false)) {
      validate = true;
    } else {
      usage_error(refine_usage, "unknown option '" + args.peek() + "' for 'refine'");
    }
  }
  if (!domain_name) usage_error(refine_usage, std::string("refine needs --domain (") + pdt_refine::domain_names() + ")");
  if (!size) usage_error(refine_usage, "refine needs --size H (the circumradius bound, e.g. 0.1)");
  if (!(*size > 0)) usage_error(refine_usage, "--size " + pdt::support::format_double(*size) + ": expected a positive number");
  if (ratio < pdt_refine::min_ratio)
    usage_error(refine_usage, "--ratio " + pdt::support::format_double(ratio) +
                                  ": expected at least 2 (below Shewchuk's bound Delaunay refinement need not terminate)");
  if (out && !ends_with_nocase(*out, ".vtu") && !ends_with_nocase(*out, ".node") && !ends_with_nocase(*out, ".ele"))
    usage_error(refine_usage, "--out " + *out + ": expected a name ending in .vtu (VTK), or .node or .ele (TetGen's pair of files)");
  // Before the run, so a typo cannot waste it: every file it will write.
  const std::vector<std::string> out_files = out ? mesh_output_files(*out) : std::vector<std::string>{};
  for (const std::string& f : out_files) require_writable_file("--out", f);
  if (trace && trace->empty()) usage_error(refine_usage, "--trace needs a file name");
  if (trace) {
    require_stream_output_name(refine_usage, "--trace", *trace);
    for (const std::string& f : out_files)
      if (same_file(f, *trace))
        usage_error(refine_usage, "--trace " + *trace + " and --out " + *out + " both write " + f +
                                      "; give the trace a name of its own");
  }
  pdt_refine::RefineOptions o;
  try {
    o.domain = pdt_refine::domain_by_name(*domain_name);
  } catch (const pdt::Error& e) {
    usage_error(refine_usage, e.what());
  }
  o.size = *size;
  o.ratio = ratio;
  o.workers = workers;
  o.seed = seed;
  o.budget = budget;
  // Written during the run, put in place at the end, with the mesh (a run
  // that fails or is interrupted before leaves an older trace as it was).
  std::optional<pdt::OpWriter> trace_writer;
  if (trace) o.trace = &trace_writer.emplace(*trace, o.domain.box);
  const bool tty = ::isatty(STDERR_FILENO) == 1;
  if (tty)
    o.progress = [](std::uint64_t vertices, std::uint64_t queued, double s) {
      std::fprintf(stderr, "\rrefining: %s vertices, %s cells to look at, %s   ", format_count(vertices).c_str(),
                   format_count(queued).c_str(), format_seconds(s).c_str());
      std::fflush(stderr);
    };

  pdt::Triangulation t;
  const pdt_refine::RefineStats st = [&] {
    try {
      return pdt_refine::refine(t, o);
    } catch (...) {
      if (tty) std::fputs("\r\033[K", stderr);  // the error gets a line of its own
      throw;
    }
  }();
  if (tty) std::fputs("\r\033[K", stderr);
  if (st.samples_over_budget) {
    // Nothing was refined: the surface's samples alone exceed the budget.
    row("domain", o.domain.name + ", size " + pdt::support::format_double(o.size));
    // The corners go in first, and every sample before the end (Refiner::start).
    row("bounds", "unfinished: " +
                      (st.surface_samples
                           ? "at this size the surface needs " + format_count(st.surface_samples) +
                                 " sample points; with the box's 8 corners that is " +
                                 format_count(st.surface_samples + 8) + ", over the point budget of "
                           : std::string("at this size the surface needs more sample points than fit the point "
                                         "budget of ")) +
                      format_count(o.budget) + " (raise --budget or --size)");
    std::fflush(summary_stream());
    return 1;  // the trace writer is discarded: an older file of its name stays
  }
  const pdt_refine::MeshQuality q = pdt_refine::measure(t, o.domain, o.size, o.ratio, o.seed, o.workers);

  char buf[256];
  row("domain", o.domain.name + ", size " + pdt::support::format_double(o.size) + ", ratio " +
                    pdt::support::format_double(o.ratio));
  row("threads", std::to_string(st.workers) + (st.workers == 1 ? " worker" : " workers") +
                     " (parallel engine, allocator " + pdt::allocator_name() + ")");
  row("vertices", format_count(t.number_of_vertices()));
  row("tets inside", format_count(q.inside) + " (of " + format_count(t.number_of_finite_cells()) + ")");
  row("insertions", format_count(st.insertions) + " (" + format_count(st.start_points) + " starting points: the box's corners and a lattice; " +
                        format_count(st.circumcentres) + " circumcentres; " + format_count(st.samples) + " of " +
                        format_count(st.surface_samples) + " surface samples)");
  row("removals", format_count(st.removals) + " (vertices too close to a surface sample)");
  row("skipped", format_count(st.dead_skipped) + " bad cells destroyed before their turn (by a neighbour's insertion), " +
                     format_count(st.died_in_engine) + " more while their insertion was queued in the engine, " +
                     format_count(st.protected_skipped) + " left in the protected layer");
  row("time", format_seconds(st.seconds) + per_second(q.inside, st.seconds) + " tets inside");
  if (q.judged > 0)
    std::snprintf(buf, sizeof buf,
                  "%.3f radius-edge (bound %.4g), circumradius %.4g (bound %.4g), over %s tets (%s more in the "
                  "protected layer along the surface; %s inside too flat for doubles to place their circumcentre)",
                  q.worst_ratio, o.ratio, q.largest_radius, o.size, format_count(q.judged).c_str(),
                  format_count(q.protected_layer).c_str(), format_count(q.unplaced).c_str());
  else  // no maximum to give
    std::snprintf(buf, sizeof buf,
                  "none judged (%s tets in the protected layer along the surface; %s inside too flat for doubles to "
                  "place their circumcentre)",
                  format_count(q.protected_layer).c_str(), format_count(q.unplaced).c_str());
  row("worst inside", buf);
  // A minimum over no tetrahedron is no angle: said in words, not as 180.
  const auto degrees = [](std::uint64_t over, double d) {
    if (over == 0) return std::string("none");
    char b[32];
    std::snprintf(b, sizeof b, "%.2f", d);
    return std::string(b);
  };
  std::snprintf(buf, sizeof buf,
                "%s degrees smallest inside, %s among the judged; %s slivers under %.0f degrees inside, %s "
                "among the judged: the radius-edge bound does not exclude slivers",
                degrees(q.inside, q.min_dihedral).c_str(), degrees(q.judged, q.min_dihedral_judged).c_str(),
                format_count(q.slivers).c_str(), pdt_refine::MeshQuality::sliver_degrees,
                format_count(q.slivers_judged).c_str());
  row("dihedral", buf);
  int status = 0;
  // "was hit", or, when the budget stopped a step of several points before
  // it was reached, what that step would have needed.
  const std::string budget_stop =
      st.budget_step > 1
          ? "the point budget of " + format_count(o.budget) + " stopped it: " + format_count(st.insertions) +
                " points in, its next step needs " + format_count(st.budget_step) + " more"
          : "the point budget of " + format_count(o.budget) + " was hit";
  if (q.violations) {
    row("bounds", format_count(q.violations) + " tets with their circumcentre inside (out of the protected layer) miss a bound" +
                      (st.budget_hit ? " (" + budget_stop + ")" : ""));
    status = 1;
  } else if (st.budget_hit) {  // an unfinished refinement: the bounds hold only on what it judged
    row("bounds", "unfinished: " + budget_stop + " (met by the tets there are, which are not a refined mesh)");
    status = 1;
  } else {
    row("bounds", std::string("met by every tet whose circumcentre is inside, out of the protected layer"));
  }
  const pdt::WorkerStats w = st.engine.total();
  std::snprintf(buf, sizeof buf,
                "%s completed, %s rollbacks, %s steals, %s escalated, imbalance %.2f; %s sleeps (%.2f s asleep), "
                "%.2f s idle (summed over workers)",
                format_count(w.completed).c_str(), format_count(w.rollbacks).c_str(), format_count(w.steals).c_str(),
                format_count(w.escalated).c_str(), st.engine.imbalance(), format_count(w.sleeps).c_str(),
                w.seconds_asleep, w.seconds_idle);
  row("workers", buf);
  if (validate) {
    std::string why;
    const bool ok = t.validate(&why);
    row("validate", ok ? std::string("ok") : "FAILED: " + why);
    if (!ok) status = 1;
  }
  // The summary so far must reach its reader before the outputs are put in
  // place: a run whose report is lost (a full disk, a closed pipe) fails
  // with the files as they were.
  require_summary_written();
  const std::uint64_t peak = pdt::support::peak_rss_bytes();  // the run's own; writing a .vtu copies the mesh
  // The trace written out and checked before the mesh is put in place, so
  // that what is left for it (a rename) can hardly fail after the mesh's.
  if (trace_writer) trace_writer->finish();
  if (out) {
    if (ends_with_nocase(*out, ".vtu")) {
      write_inside_vtu(*out, t, o.domain);
    } else {
      pdt::write_tetgen(*out, t);
    }
  }
  if (trace_writer) trace_writer->close();
  if (trace) outputs_in_place(*trace);
  if (out) {
    const pdt::TetgenFiles files = pdt::tetgen_files(*out);
    const std::string written = ends_with_nocase(*out, ".vtu") ? *out : files.node + " and " + files.ele;
    outputs_in_place(written);
    row("wrote", written);
  }
  if (trace)
    row("trace", writes_standard_output(*trace) ? *trace : *trace + " (pdt run " + *trace + " --threads N replays it)");
  peak_memory_row(peak, out ? " with writing the mesh" : nullptr);
  std::fflush(summary_stream());
  return status;
}

}  // namespace pdt_cli
