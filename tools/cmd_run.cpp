// SPDX-License-Identifier: MIT
// pdt run: replays an operation stream, read as it goes (so memory follows
// the live mesh, not the stream's length), or triangulates a point file; on
// the sequential kernel or the parallel engine; then prints a summary.
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/task_arena.h>
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "cli.hpp"
#include "pdt/pdt.hpp"
#include "support/cli_text.hpp"
#include "support/sys_info.hpp"

namespace pdt_cli {

using pdt::support::ends_with_nocase;
using pdt::support::format_count;
using pdt::support::format_megabytes;
using pdt::support::format_seconds;

const char* const run_usage =
    "usage: pdt run INPUT [options]\n"
    "\n"
    "Replays INPUT on a triangulation and prints a summary. INPUT is an\n"
    "operation stream (.ops text or .opsb binary, possibly gzipped), read as it\n"
    "is replayed, or a point file (.xyz, .xyz.gz, .ply, .off, .node, .smesh),\n"
    "whose points are inserted as a batch in spatial order (the fast way).\n"
    "\n"
    "options:\n"
    "  --threads N     run on the parallel engine with N workers (0 = one per core), in a TBB\n"
    "                  arena of N threads or one per core if fewer; without it the sequential\n"
    "                  kernel replays the stream. The engine's other settings come from PDT_*\n"
    "                  variables (see README); --threads sets the workers, not PDT_WORKERS\n"
    "  --in-order      point files: insert in file order, one point at a time\n"
    "  --in-flight N   engine: at most N operations submitted and not yet done (default\n"
    "                  65536, or 4096 per worker if more); the reader waits (back-pressure);\n"
    "                  with --threads, for a stream or a point file read --in-order\n"
    "  --out FILE      write the final mesh: FILE.node (TetGen .node + .ele) or FILE.vtu\n"
    "                  (VTK, binary, zlib-compressed; --vtu-ascii for text)\n"
    "  --vtu-ascii     write .vtu as ASCII text\n"
    "  --shrink        after the replay, give the storage of freed cells and vertices back\n"
    "                  (Triangulation::shrink_to_fit) and report the memory before and after\n"
    "  --validate      check every invariant of the final triangulation (exit 1 if broken)\n";

namespace {

using Kind = pdt::Operation::Kind;

struct ReplayStats {
  std::uint64_t insertions = 0, duplicates = 0, removals = 0, multiplicity_lowered = 0, operations = 0;
  double insert_seconds = 0, remove_seconds = 0, mixed_seconds = 0;
  std::uint64_t peak_in_flight = 0;
  bool engine = false;
  unsigned workers = 1, blocks_per_axis = 0;
  pdt::EngineStats engine_stats;
};

// Times the runs of insertions and of removals apart when they are long (the
// paper's "insert all, then remove"), or everything as one mixed phase when
// the stream interleaves them. `settle` waits for the work submitted so far
// (the engine's drain; nothing for the kernel), so that a phase's time is its own.
class PhaseClock {
 public:
  static constexpr std::uint64_t long_run = 16384;
  template <class Settle>
  void op(Kind k, Settle&& settle) {
    if (started_ && k != current_) {
      if (run_ >= long_run && phased_) {
        settle();
        (current_ == Kind::insert ? st_.insert_seconds : st_.remove_seconds) += clock_.seconds();
        clock_.restart();
      } else {
        phased_ = false;
      }
      run_ = 0;
    }
    current_ = k;
    started_ = true;
    ++run_;
  }
  template <class Settle>
  void finish(Settle&& settle) {
    settle();
    if (!started_) return;
    if (phased_)
      (current_ == Kind::insert ? st_.insert_seconds : st_.remove_seconds) += clock_.seconds();
    else
      st_.mixed_seconds = total_.seconds();
  }
  explicit PhaseClock(ReplayStats& st) : st_(st) {}

 private:
  ReplayStats& st_;
  Kind current_ = Kind::insert;
  bool started_ = false;
  std::uint64_t run_ = 0;
  bool phased_ = true;
  pdt::support::Stopwatch clock_, total_;
};

// What the engine's callbacks count. Callbacks capture one pointer to it, so
// std::function keeps them in place (no allocation per operation).
struct Tally {
  std::atomic<std::uint64_t> duplicates{0}, lowered{0}, failures{0};
  std::atomic<std::uint64_t> in_flight{0};
  std::uint64_t limit = 0;
  std::mutex mutex;
  std::string first_error;
  void done(const pdt::OpResult& r) {
    if (r.error) {
      if (failures.fetch_add(1) == 0) {
        std::lock_guard lock(mutex);
        try {
          std::rethrow_exception(r.error);
        } catch (const std::exception& e) {
          first_error = e.what();
        }
      }
    } else if (r.kind == pdt::OpKind::insert) {
      if (!r.insert.inserted) duplicates.fetch_add(1, std::memory_order_relaxed);
    } else if (r.remove == pdt::RemoveResult::multiplicity_lowered) {
      lowered.fetch_add(1, std::memory_order_relaxed);
    }
    // Back-pressure: the reader waits until half the limit has drained.
    if (in_flight.fetch_sub(1, std::memory_order_acq_rel) == limit / 2 + 1) in_flight.notify_all();
  }
};

// An engine in its own arena with the tally of its results. The submitting
// thread stays outside the arena, so all N threads work while it waits for
// room; a worker count of N needs N + 1 threads in all.
struct EngineRun {
  Tally tally;
  unsigned threads;
  tbb::global_control parallelism;
  tbb::task_arena arena;
  pdt::Engine engine;

  EngineRun(pdt::Triangulation& t, const pdt::Box& box, unsigned workers, std::uint64_t limit)
      : threads(std::min(workers, std::max(1u, std::thread::hardware_concurrency()))),
        parallelism(tbb::global_control::max_allowed_parallelism,
                    std::max<std::size_t>(threads + 1, tbb::global_control::active_value(
                                                           tbb::global_control::max_allowed_parallelism))),
        arena(static_cast<int>(threads), 0),
        engine(t, box, options(workers), &arena) {
    tally.limit = std::max<std::uint64_t>(limit, 2);
  }
  static pdt::EngineOptions options(unsigned workers) {
    pdt::EngineOptions opts = pdt::EngineOptions::from_environment();
    opts.workers = workers;
    return opts;
  }
  pdt::Engine::Callback callback() {
    Tally* tp = &tally;
    return [tp](const pdt::OpResult& r) { tp->done(r); };
  }
  // After drain(): the engine's figures into st, or the first failure thrown.
  void finish(ReplayStats& st, const char* what) {
    st.engine = true;
    st.engine_stats = engine.stats();
    st.workers = engine.workers();
    st.blocks_per_axis = engine.blocks_per_axis();
    if (tally.failures.load())
      throw pdt::Error(pdt::ErrorCode::invalid_argument, std::to_string(tally.failures.load()) + " " + what +
                                                             " failed on the engine; the first: " + tally.first_error);
    st.duplicates = tally.duplicates.load();
    st.multiplicity_lowered = tally.lowered.load();
  }
};

// The domain an engine needs: the stream's box, or (a first pass over the
// stream) its points' bounding box.
pdt::Box stream_box(const std::string& path, const std::optional<pdt::Box>& declared) {
  if (declared) return *declared;
  // Without a box line the stream is read twice, first for its points' box:
  // a pipe cannot be.
  struct stat st;
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode))
    throw pdt::Error(pdt::ErrorCode::invalid_argument,
                     path + ": the engine (--threads) needs the stream's domain before its first operation: "
                            "give the stream a 'box x0 y0 z0 x1 y1 z1' line, or replay it from a regular file "
                            "(read twice, the first time for its box), not a pipe");
  pdt::OpReader r(path);
  pdt::Box b{{HUGE_VAL, HUGE_VAL, HUGE_VAL}, {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL}};
  pdt::Operation op;
  while (r.next(op)) {
    if (op.kind != Kind::insert) continue;
    b.lo = {std::min(b.lo.x, op.point.x), std::min(b.lo.y, op.point.y), std::min(b.lo.z, op.point.z)};
    b.hi = {std::max(b.hi.x, op.point.x), std::max(b.hi.y, op.point.y), std::max(b.hi.z, op.point.z)};
  }
  if (b.lo.x > b.hi.x) b = pdt::Box{};  // no insertion at all
  return b;
}

pdt::Box points_box(const std::vector<pdt::Point3>& pts) {
  if (pts.empty()) return {};
  pdt::Box b{pts.front(), pts.front()};
  for (const auto& p : pts) {
    b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
    b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
  }
  return b;
}

std::string op_context(std::uint64_t i, const pdt::Operation& op, std::uint64_t insertion) {
  return "operation " + std::to_string(i) +
         (op.kind == Kind::insert ? " (insertion " + std::to_string(insertion) + ")"
                                  : " (removal of insertion " + std::to_string(op.target) + ")");
}

// The sequential kernel, one operation at a time. vertex_of holds the live
// insertions' vertices only: erased when undone.
ReplayStats replay_stream_sequential(pdt::OpReader& reader, pdt::Triangulation& t) {
  ReplayStats st;
  PhaseClock phases(st);
  std::unordered_map<std::uint64_t, pdt::VertexId> vertex_of;
  pdt::support::ProgressBar bar("replaying", reader.announced_count().value_or(0));
  pdt::Operation op;
  auto nothing = [] {};
  while (reader.next(op)) {
    phases.op(op.kind, nothing);
    try {
      if (op.kind == Kind::insert) {
        const pdt::InsertResult r = t.insert(op.point);
        vertex_of.emplace(st.insertions++, r.vertex);
        st.duplicates += !r.inserted;
      } else {
        auto it = vertex_of.find(op.target);
        const pdt::RemoveResult r = t.remove(it->second);  // the reader checked that it is live
        vertex_of.erase(it);
        ++st.removals;
        st.multiplicity_lowered += r == pdt::RemoveResult::multiplicity_lowered;
      }
    } catch (const pdt::Error& e) {
      throw pdt::Error(e.code(), op_context(st.operations, op, st.insertions) + ": " + e.what());
    }
    bar.update(++st.operations);
  }
  phases.finish(nothing);
  bar.finish();
  return st;
}

// The engine: insertion k of the stream is the engine's ticket k and 'r k' is
// remove_insertion(k), which waits for insertion k by itself, so the stream
// is submitted without barriers, at most `limit` operations ahead.
ReplayStats replay_stream_engine(pdt::OpReader& reader, const pdt::Box& box, unsigned workers, std::uint64_t limit,
                                 pdt::Triangulation& t) {
  ReplayStats st;
  EngineRun run(t, box, workers, limit);
  Tally& tally = run.tally;
  pdt::Engine& engine = run.engine;
  const pdt::Engine::Callback done = run.callback();
  PhaseClock phases(st);
  auto settle = [&] { engine.drain(); };
  pdt::support::ProgressBar bar("replaying", reader.announced_count().value_or(0));
  pdt::Operation op;
  while (reader.next(op)) {
    phases.op(op.kind, settle);
    std::uint64_t now = tally.in_flight.fetch_add(1, std::memory_order_acq_rel) + 1;
    st.peak_in_flight = std::max(st.peak_in_flight, now);
    try {
      if (op.kind == Kind::insert) {
        (void)engine.insert(op.point, done);
        ++st.insertions;
      } else {
        engine.remove_insertion(op.target, done);
        ++st.removals;
      }
    } catch (const pdt::Error& e) {
      tally.in_flight.fetch_sub(1);
      throw pdt::Error(e.code(), op_context(st.operations, op, st.insertions) + ": " + e.what());
    }
    while ((now = tally.in_flight.load(std::memory_order_acquire)) >= tally.limit) tally.in_flight.wait(now);
    bar.update(++st.operations);
  }
  phases.finish(settle);
  bar.finish();
  run.finish(st, "operation(s)");
  return st;
}

// A point file: all at once, as a batch in spatial order (or in file order,
// one at a time, with --in-order).
ReplayStats insert_points(const std::vector<pdt::Point3>& pts, unsigned workers, bool in_order, std::uint64_t limit,
                          pdt::Triangulation& t) {
  ReplayStats st;
  st.insertions = st.operations = pts.size();
  pdt::support::Stopwatch sw;
  if (!workers) {
    if (in_order) {
      pdt::support::ProgressBar bar("inserting", pts.size());
      for (std::size_t i = 0; i < pts.size(); ++i) {
        st.duplicates += !t.insert(pts[i]).inserted;
        bar.update(i + 1);
      }
    } else {
      for (const pdt::InsertResult& r : t.insert_batch(pts)) st.duplicates += !r.inserted;
    }
    st.insert_seconds = sw.seconds();
    return st;
  }
  EngineRun run(t, points_box(pts), workers, limit);
  Tally& tally = run.tally;
  pdt::Engine& engine = run.engine;
  const pdt::Engine::Callback done = run.callback();
  if (in_order) {
    for (const pdt::Point3& p : pts) {
      std::uint64_t now = tally.in_flight.fetch_add(1) + 1;
      (void)engine.insert(p, done);
      while ((now = tally.in_flight.load(std::memory_order_acquire)) >= tally.limit) tally.in_flight.wait(now);
    }
  } else {
    tally.in_flight.fetch_add(pts.size());
    tally.limit = ~std::uint64_t{0};  // no one waits on a batch
    engine.insert_batch(pts, done);
  }
  engine.drain();
  st.insert_seconds = sw.seconds();
  run.finish(st, "insertion(s)");
  return st;
}

void print_engine_stats(const ReplayStats& st) {
  const pdt::WorkerStats w = st.engine_stats.total();
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "%s completed, %s attempts, %s rollbacks, %s deferred, %s sleeps (%.3f s asleep), %.3f s idle, %s "
                "steals, %s escalated",
                format_count(w.completed).c_str(), format_count(w.attempts).c_str(), format_count(w.rollbacks).c_str(),
                format_count(w.deferred).c_str(), format_count(w.sleeps).c_str(), w.seconds_asleep, w.seconds_idle,
                format_count(w.steals).c_str(), format_count(w.escalated).c_str());
  row("workers", buf);
  std::snprintf(buf, sizeof buf, "%.4f%% (max over workers); %s operations ran with the world stopped",
                100.0 * w.max_rollbacks_per_completed, format_count(st.engine_stats.global_operations).c_str());
  row("rollbacks/op", buf);
  std::snprintf(buf, sizeof buf, "%.2f (max / mean completed per worker; 1 = even); blocks re-cut %s times",
                st.engine_stats.imbalance(), format_count(st.engine_stats.recuts).c_str());
  row("imbalance", buf);
  if (st.engine_stats.workers.size() <= 64) {
    std::string per = "completed/steals:";
    for (const pdt::WorkerStats& ws : st.engine_stats.workers) {
      per += ' ';
      per += format_count(ws.completed);
      per += '/';
      per += format_count(ws.steals);
    }
    row("per worker", per);
  }
  if (st.peak_in_flight) row("in flight", "at most " + format_count(st.peak_in_flight) + " operations");
}

}  // namespace

int cmd_run(Args args) {
  std::optional<std::string> input, out;
  unsigned workers = 0;  // 0: the sequential kernel
  bool validate = false, in_order = false, vtu_ascii = false, shrink = false;
  std::uint64_t in_flight = 0;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(run_usage, stdout);
      return 0;
    }
    if (args.option("--threads", true)) {
      workers = parse_workers_option(args, args.value());
    } else if (args.option("--in-flight", true)) {
      in_flight = parse_count_option(args, "--in-flight", args.value());
      if (in_flight < 2) usage_error(run_usage, "--in-flight " + args.value() + ": expected at least 2");
    } else if (args.option("--out", true)) {
      out = args.value();
    } else if (args.option("--in-order", false)) {
      in_order = true;
    } else if (args.option("--vtu-ascii", false)) {
      vtu_ascii = true;
    } else if (args.option("--validate", false)) {
      validate = true;
    } else if (args.option("--shrink", false)) {
      shrink = true;
    } else if (args.peek().size() > 1 && args.peek()[0] == '-') {
      usage_error(run_usage, "unknown option '" + args.peek() + "' for 'run'");
    } else if (input) {
      usage_error(run_usage, "run takes one input file; got '" + *input + "' and '" + args.peek() + "'");
    } else {
      input = args.next();
    }
  }
  if (!input) usage_error(run_usage, "run needs an input file");
  for (const char* ext : {".ply.gz", ".off.gz", ".node.gz", ".smesh.gz"})
    if (ends_with_nocase(*input, ext))
      usage_error(run_usage, *input + ": gzipped " + std::string(ext, std::strlen(ext) - 3) +
                                 " files are not read (.xyz.gz and streams are); gunzip it first");
  enum class OutKind { none, tetgen, vtu } out_kind = OutKind::none;
  if (out) {
    // Decide before the (possibly long) run, so a typo cannot waste it.
    if (ends_with_nocase(*out, ".node") || ends_with_nocase(*out, ".ele")) out_kind = OutKind::tetgen;
    else if (ends_with_nocase(*out, ".vtu")) out_kind = OutKind::vtu;
    else usage_error(run_usage, "--out " + *out + ": expected a name ending in .node or .ele (TetGen's pair of files) or .vtu (VTK)");
    for (const std::string& f : mesh_output_files(*out)) {
      require_writable_file("--out", f);
      if (same_file(f, *input)) usage_error(run_usage, "--out " + *out + " would overwrite the input " + *input);
      // A .smesh whose header holds no nodes reads them from the .node beside it.
      if (ends_with_nocase(*input, ".smesh")) {
        const std::string nodes = input->substr(0, input->size() - 6) + ".node";
        if (same_file(f, nodes))
          usage_error(run_usage, "--out " + *out + " would overwrite " + nodes + ", where the input " + *input +
                                     " may take its points from");
      }
    }
  }
  if (in_flight && (!workers || (is_point_file(*input) && !in_order)))
    usage_error(run_usage, "--in-flight applies to the engine's operations one at a time: give --threads N, and for "
                           "a point file --in-order (a batch submits every point at once)");
  if (vtu_ascii && out_kind != OutKind::vtu)
    usage_error(run_usage, "--vtu-ascii applies to a .vtu output; give --out FILE.vtu (or drop --vtu-ascii)");
  if (in_order && !is_point_file(*input))
    usage_error(run_usage, "--in-order applies to point files; an operation stream is always replayed in its order");
  // The window is what the blocks can reorder: with 4,096 operations per worker, 1M random
  // points on 1 worker took 6.2 s, with 65,536 4.3 s (the batch: 3.0 s), for 14 MB more.
  if (!in_flight) in_flight = std::max<std::uint64_t>(65536, std::uint64_t{4096} * std::max(1u, workers));

  pdt::Triangulation t;
  ReplayStats st;
  std::optional<pdt::Box> box;
  double read_seconds = 0;
  const bool points = is_point_file(*input);
  if (points) {
    pdt::support::Stopwatch read_sw;
    const std::vector<pdt::Point3> pts = pdt::read_points(*input);
    read_seconds = read_sw.seconds();
    st = insert_points(pts, workers, in_order, in_flight, t);
  } else {
    pdt::OpReader reader(*input);
    box = reader.box();
    if (workers) {
      const pdt::Box domain = stream_box(*input, box);
      st = replay_stream_engine(reader, domain, workers, in_flight, t);
    } else {
      st = replay_stream_sequential(reader, t);
    }
  }

  row("input", *input + (box ? ", box " + box_string(*box) : "") +
                   (points ? (in_order ? " (points in file order)" : " (points as a batch, spatial order)") : ""));
  row("threads", st.engine ? std::to_string(st.workers) + (st.workers == 1 ? " worker" : " workers") + " (parallel engine, " +
                                 std::to_string(st.blocks_per_axis) + "^3 blocks, allocator " + pdt::allocator_name() +
                                 ")"
                           : std::string("1 (sequential kernel)"));
  row("vertices", format_count(t.number_of_vertices()));
  row("finite tets", format_count(t.number_of_finite_cells()));
  row("insertions", format_count(st.insertions) + " (" + format_count(st.duplicates) + " duplicates)");
  row("removals", format_count(st.removals) +
                      (st.multiplicity_lowered ? " (" + format_count(st.multiplicity_lowered) + " lowered a multiplicity)" : ""));
  if (points) row("read time", format_seconds(read_seconds));
  if (st.mixed_seconds > 0) {
    row("mixed time", format_seconds(st.mixed_seconds) + " (insertions and removals interleaved; reading included)");
  } else {
    row("insert time", format_seconds(st.insert_seconds) + per_second(st.insertions, st.insert_seconds));
    if (!points) row("remove time", format_seconds(st.remove_seconds) + per_second(st.removals, st.remove_seconds));
  }
  const double total = st.insert_seconds + st.remove_seconds + st.mixed_seconds;
  row("operations/s", total > 0 ? format_count(static_cast<std::uint64_t>(static_cast<double>(st.operations) / total))
                                : std::string("n/a"));
  if (st.insertions) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%.1f per insertion (visibility walk; locations of other kinds included)",
                  static_cast<double>(t.stats().walk_steps) / static_cast<double>(st.insertions));
    row("walk steps", buf);
  }
  // Before the mesh is written, which copies it (extract_mesh): the run's own peak.
  const std::uint64_t peak = pdt::support::peak_rss_bytes();
  if (st.engine) print_engine_stats(st);

  if (shrink) {  // before validate, which reads every vertex record
    const std::size_t bytes = t.memory_bytes();
    const std::uint64_t resident = pdt::support::current_rss_bytes();
    pdt::support::Stopwatch ssw;
    t.shrink_to_fit();
    const double seconds = ssw.seconds();
    row("shrink", "the mesh " + pdt::support::format_megabytes(bytes) + " -> " +
                      pdt::support::format_megabytes(t.memory_bytes()) + " (memory_bytes), resident " +
                      pdt::support::format_megabytes(resident) + " -> " +
                      pdt::support::format_megabytes(pdt::support::current_rss_bytes()) + ", in " +
                      format_seconds(seconds));
  }
  int status = 0;
  if (validate) {
    pdt::support::Stopwatch vsw;
    std::string why;
    const bool ok = t.validate(&why);
    row("validate", (ok ? std::string("ok") : "FAILED: " + why) + " (" + format_seconds(vsw.seconds()) + ")");
    if (!ok) status = 1;
  }
  if (out_kind != OutKind::none) {
    require_summary_written();  // a lost summary fails the run with the files as they were
    const pdt::Mesh m = pdt::extract_mesh(t);
    if (out_kind == OutKind::tetgen) pdt::write_tetgen(*out, m);
    else pdt::write_vtu(*out, m, vtu_ascii ? pdt::VtuEncoding::ascii : pdt::VtuEncoding::zlib);
    // write_tetgen writes a .node and a .ele, whichever of the two (in any
    // case) --out named: say which files those are.
    std::string written = *out;
    if (out_kind == OutKind::tetgen) {
      const pdt::TetgenFiles files = pdt::tetgen_files(*out);
      written = files.node + " and " + files.ele;
    }
    outputs_in_place(written);
    row("wrote", written + " (" + format_count(m.points.size()) + " points, " + format_count(m.tets.size()) + " tets)");
  }
  peak_memory_row(peak, out_kind != OutKind::none ? " with writing the mesh (a copy of it)" : nullptr);
  if (t.number_of_vertices()) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "%.0f (peak memory / live vertices); the mesh itself: %.0f",
                  static_cast<double>(peak) / static_cast<double>(t.number_of_vertices()),
                  static_cast<double>(t.memory_bytes()) / static_cast<double>(t.number_of_vertices()));
    row("bytes/vertex", buf);
  }
  std::fflush(summary_stream());
  return status;
}

}  // namespace pdt_cli
