// pdt: command-line tool to generate operation streams, replay them on a
// triangulation, and check meshes. Run `pdt --help`.
//
// Exit status: 0 success; 1 a check failed (`check` found an invalid mesh,
// `run --validate` found a broken triangulation); 2 usage error or any failure
// (bad input, I/O). Every failure is one "pdt: ..." line on stderr; nothing
// escapes as an uncaught exception.
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "pdt/pdt.hpp"
#include "support/cli_text.hpp"
#include "support/sys_info.hpp"

namespace {

using pdt::support::ends_with_nocase;
using pdt::support::format_count;
using pdt::support::format_megabytes;
using pdt::support::format_seconds;

// ---- usage -------------------------------------------------------------------

const char* const kMainUsage =
    "usage: pdt <command> [options]\n"
    "\n"
    "commands:\n"
    "  gen    generate an operation stream (insertions, removals)\n"
    "  run    replay an operation stream (or a point file) on a triangulation\n"
    "  check  check that a TetGen mesh is a Delaunay tetrahedralization\n"
    "\n"
    "Run 'pdt <command> --help' for a command's options.\n"
    "Exit status: 0 success, 1 check failed, 2 error.\n";

const char* const kGenUsage =
    "usage: pdt gen --points N --out FILE.ops|FILE.opsb [options]\n"
    "\n"
    "Writes a synthetic operation stream: N insertions, then (or interleaved\n"
    "with them) the removal of the first floor(F*N) inserted points.\n"
    "\n"
    "options:\n"
    "  --dist D               uniform (default), normal, line, grid, sphere\n"
    "  --points N             number of insertions (e.g. 1000000 or 1e6)\n"
    "  --remove-fraction F    fraction in [0, 1] of the insertions to undo (default 0)\n"
    "  --interleaved          put each removal soon after its insertion (default: all at the end)\n"
    "  --seed S               random seed (default 1); same seed, same stream, on any platform\n"
    "  --out FILE             .opsb writes the binary form, anything else text\n";

const char* const kRunUsage =
    "usage: pdt run INPUT [options]\n"
    "\n"
    "Replays INPUT on a triangulation and prints a summary. INPUT is an\n"
    "operation stream (.ops text or .opsb binary, possibly gzipped) or a point\n"
    "file (.xyz, .xyz.gz, .ply, .off, .node, .smesh: its points are inserted in\n"
    "file order).\n"
    "\n"
    "options:\n"
    "  --threads N     run on the parallel engine with N workers in a TBB arena of N threads\n"
    "                  (0 = all cores); without it the sequential kernel replays the stream.\n"
    "                  The engine's other settings come from PDT_* variables (see README)\n"
    "  --out FILE      write the final mesh: FILE.node (TetGen .node + .ele) or FILE.vtu (VTK)\n"
    "  --validate      check every invariant of the final triangulation (exit 1 if broken)\n";

const char* const kCheckUsage =
    "usage: pdt check MESH.node\n"
    "\n"
    "Reads a TetGen mesh (MESH.node and MESH.ele) and checks, with exact\n"
    "predicates, that it is a Delaunay tetrahedralization of its points.\n"
    "Exit status: 0 valid, 1 invalid, 2 error.\n";

// A command-line mistake: reported with the command's usage, exit 2.
struct UsageError {
  std::string message;
  const char* usage;
};

[[noreturn]] void usage_error(const char* usage, std::string msg) { throw UsageError{std::move(msg), usage}; }

bool is_help(const std::string& a) { return a == "--help" || a == "-h"; }

// Options of the form "--name value" or "--name=value".
class Args {
 public:
  Args(std::vector<std::string> a, const char* usage) : a_(std::move(a)), usage_(usage) {}
  bool done() const { return i_ >= a_.size(); }
  const std::string& peek() const { return a_[i_]; }
  std::string next() { return a_[i_++]; }
  // If the current argument is option `name`, consumes it and returns true;
  // the value (for options that take one) is then in value().
  bool option(const char* name, bool takes_value) {
    const std::string& a = a_[i_];
    const std::size_t n = std::strlen(name);
    if (a.compare(0, n, name) != 0) return false;
    if (a.size() == n) {
      ++i_;
      if (takes_value) {
        if (done()) usage_error(usage_, std::string("option ") + name + " needs a value");
        value_ = a_[i_++];
      }
      return true;
    }
    if (a[n] != '=') return false;
    if (!takes_value) usage_error(usage_, std::string("option ") + name + " takes no value");
    value_ = a.substr(n + 1);
    ++i_;
    return true;
  }
  const std::string& value() const { return value_; }
  const char* usage() const { return usage_; }

 private:
  std::vector<std::string> a_;
  std::size_t i_ = 0;
  std::string value_;
  const char* usage_;
};

// A non-negative integer option value: "1000000", or "1e6" when integral.
std::uint64_t parse_count_option(const Args& args, const char* name, const std::string& v) {
  unsigned long long n = 0;
  if (pdt::support::parse_count(v, n)) return n;
  usage_error(args.usage(), std::string(name) + " '" + v + "': expected a non-negative integer");
}

double parse_real_option(const Args& args, const char* name, const std::string& v) {
  double d = 0;
  if (!pdt::support::parse_real(v, d))
    usage_error(args.usage(), std::string(name) + " '" + v + "': expected a number");
  return d;
}

std::string box_string(const pdt::Box& b) {
  using pdt::support::format_double;
  return "[" + format_double(b.lo.x) + ", " + format_double(b.hi.x) + "] x [" + format_double(b.lo.y) + ", " +
         format_double(b.hi.y) + "] x [" + format_double(b.lo.z) + ", " + format_double(b.hi.z) + "]";
}

void row(const char* key, const std::string& value) { std::printf("%-16s %s\n", key, value.c_str()); }

std::string per_second(std::uint64_t n, double s) {
  if (n == 0 || s <= 0) return "";
  return " (" + format_count(static_cast<std::uint64_t>(static_cast<double>(n) / s)) + "/s)";
}

// ---- gen ---------------------------------------------------------------------

int cmd_gen(Args args) {
  pdt::GenerateOptions o;
  std::optional<std::string> out;
  bool have_points = false;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(kGenUsage, stdout);
      return 0;
    }
    if (args.option("--dist", true)) {
      try {
        o.dist = pdt::parse_distribution(args.value());
      } catch (const pdt::Error& e) {
        usage_error(kGenUsage, e.what());
      }
    } else if (args.option("--points", true)) {
      o.points = parse_count_option(args, "--points", args.value());
      have_points = true;
    } else if (args.option("--remove-fraction", true)) {
      o.remove_fraction = parse_real_option(args, "--remove-fraction", args.value());
      if (!(o.remove_fraction >= 0 && o.remove_fraction <= 1))
        usage_error(kGenUsage, "--remove-fraction " + args.value() + ": expected a number in [0, 1]");
    } else if (args.option("--interleaved", false)) {
      o.removal_order = pdt::RemovalOrder::interleaved;
    } else if (args.option("--seed", true)) {
      o.seed = parse_count_option(args, "--seed", args.value());
    } else if (args.option("--out", true)) {
      out = args.value();
    } else {
      usage_error(kGenUsage, "unknown option '" + args.peek() + "' for 'gen'");
    }
  }
  if (!have_points) usage_error(kGenUsage, "gen needs --points N");
  if (!out || out->empty()) usage_error(kGenUsage, "gen needs --out FILE");
  pdt::support::Stopwatch sw;
  const pdt::OpStream s = pdt::generate(o);
  pdt::write_ops(*out, s);
  std::printf("wrote %s: %s insertions, %s removals (%s, seed %llu), box %s, in %s\n", out->c_str(),
              format_count(s.insert_count()).c_str(), format_count(s.remove_count()).c_str(), pdt::to_string(o.dist),
              static_cast<unsigned long long>(o.seed), box_string(*s.box).c_str(), format_seconds(sw.seconds()).c_str());
  return 0;
}

// ---- run -----------------------------------------------------------------------

struct ReplayStats {
  std::uint64_t insertions = 0, duplicates = 0, removals = 0, multiplicity_lowered = 0;
  double insert_seconds = 0, remove_seconds = 0, mixed_seconds = 0;
  unsigned threads_used = 1;
  bool engine = false;
  pdt::EngineStats engine_stats;
  unsigned blocks_per_axis = 0;
};

// The domain an engine needs: the stream's box, or the points' bounding box.
pdt::Box stream_box(const pdt::OpStream& s) {
  if (s.box) return *s.box;
  pdt::Box b{{HUGE_VAL, HUGE_VAL, HUGE_VAL}, {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL}};
  for (const pdt::Operation& op : s.ops) {
    if (op.kind != pdt::Operation::Kind::insert) continue;
    b.lo = {std::min(b.lo.x, op.point.x), std::min(b.lo.y, op.point.y), std::min(b.lo.z, op.point.z)};
    b.hi = {std::max(b.hi.x, op.point.x), std::max(b.hi.y, op.point.y), std::max(b.hi.z, op.point.z)};
  }
  if (b.lo.x > b.hi.x) b = pdt::Box{};  // no insertion at all
  return b;
}

// Replays a stream on the parallel engine: insertion k is the engine's ticket
// k, and 'r k' is remove_insertion(k), which waits for insertion k by itself,
// so the stream is submitted without barriers. A stream that switches between
// inserting and removing at most twice (the paper's "insert all, then remove")
// is drained at each switch, to time the phases apart; otherwise the whole
// run is timed as one mixed phase.
ReplayStats replay_engine(const pdt::OpStream& s, unsigned threads, pdt::Triangulation& t) {
  using Kind = pdt::Operation::Kind;
  ReplayStats st;
  st.engine = true;
  std::size_t switches = 0;
  for (std::size_t i = 1; i < s.ops.size(); ++i) switches += s.ops[i].kind != s.ops[i - 1].kind;
  const bool phased = switches <= 2;
  std::atomic<std::uint64_t> duplicates{0}, lowered{0}, failures{0};
  std::string first_error;
  std::atomic<bool> have_error{false};
  auto on_done = [&](const pdt::OpResult& r) {
    if (r.error) {
      failures.fetch_add(1);
      if (!have_error.exchange(true)) {
        try {
          std::rethrow_exception(r.error);
        } catch (const std::exception& e) {
          first_error = e.what();
        }
      }
      return;
    }
    if (!r.insert.inserted && r.insert.vertex != pdt::no_vertex) duplicates.fetch_add(1, std::memory_order_relaxed);
    if (r.remove == pdt::RemoveResult::multiplicity_lowered) lowered.fetch_add(1, std::memory_order_relaxed);
  };
  pdt::EngineOptions opts = pdt::EngineOptions::from_environment();
  opts.workers = threads;
  // Workers are coroutines, not threads: N workers run in an arena no wider
  // than the machine, so --threads 16 on 2 cores still exercises 16 workers.
  tbb::task_arena arena(static_cast<int>(std::min(threads, std::max(1u, std::thread::hardware_concurrency()))));
  pdt::support::ProgressBar bar("replaying", s.ops.size());
  arena.execute([&] {
    pdt::Engine engine(t, stream_box(s), opts);
    pdt::support::Stopwatch phase;
    std::optional<Kind> current;
    auto close_phase = [&] {
      if (!current) return;
      engine.drain();
      (phased ? (*current == Kind::insert ? st.insert_seconds : st.remove_seconds) : st.mixed_seconds) +=
          phase.seconds();
      phase.restart();
    };
    for (std::size_t i = 0; i < s.ops.size(); ++i) {
      const pdt::Operation& op = s.ops[i];
      if (phased && current && op.kind != *current) close_phase();
      current = op.kind;
      if (op.kind == Kind::insert) {
        engine.insert(op.point, on_done);
        ++st.insertions;
      } else {
        engine.remove_insertion(op.target, on_done);
        ++st.removals;
      }
      if ((i & 1023) == 0) bar.update(i + 1);
    }
    close_phase();
    st.engine_stats = engine.stats();
    st.threads_used = engine.workers();
    st.blocks_per_axis = engine.blocks_per_axis();
  });
  bar.finish();
  if (failures.load())
    throw pdt::Error(pdt::ErrorCode::invalid_argument,
                     std::to_string(failures.load()) + " operation(s) failed on the engine; the first: " + first_error);
  st.duplicates = duplicates.load();
  st.multiplicity_lowered = lowered.load();
  return st;
}

// Replays a validated stream (read_ops checked every 'r k' and the box).
// vertex_of[k] is the vertex insertion k produced (or found, for a duplicate);
// the kernel keeps multiplicities, so 'r k' is always remove(vertex_of[k]).
// Time is split by runs of same-kind operations: one clock read per switch
// between inserting and removing, not per operation.
ReplayStats replay(const pdt::OpStream& s, pdt::Triangulation& t) {
  ReplayStats st;
  std::vector<pdt::VertexId> vertex_of;
  vertex_of.reserve(s.insert_count());
  pdt::support::ProgressBar bar("replaying", s.ops.size());
  pdt::support::Stopwatch ins, rem;
  ins.stop();
  rem.stop();
  using Kind = pdt::Operation::Kind;
  std::optional<Kind> current;
  for (std::size_t i = 0; i < s.ops.size(); ++i) {
    const pdt::Operation& op = s.ops[i];
    if (op.kind != current) {
      if (current) (*current == Kind::insert ? ins : rem).stop();
      (op.kind == Kind::insert ? ins : rem).resume();
      current = op.kind;
    }
    try {
      if (op.kind == Kind::insert) {
        const pdt::InsertResult r = t.insert(op.point);
        vertex_of.push_back(r.vertex);
        ++st.insertions;
        st.duplicates += !r.inserted;
      } else {
        const pdt::RemoveResult r = t.remove(vertex_of[op.target]);
        ++st.removals;
        st.multiplicity_lowered += r == pdt::RemoveResult::multiplicity_lowered;
      }
    } catch (const pdt::Error& e) {
      throw pdt::Error(e.code(), "operation " + std::to_string(i) +
                                     (op.kind == Kind::insert ? " (insertion " + std::to_string(vertex_of.size()) + ")"
                                                              : " (removal of insertion " + std::to_string(op.target) + ")") +
                                     ": " + e.what());
    }
    bar.update(i + 1);
  }
  ins.stop();
  rem.stop();
  bar.finish();
  st.insert_seconds = ins.seconds();
  st.remove_seconds = rem.seconds();
  return st;
}

bool is_point_file(const std::string& p) {
  for (const char* ext : {".xyz", ".xyz.gz", ".ply", ".off", ".node", ".smesh"})
    if (ends_with_nocase(p, ext)) return true;
  return false;
}

int cmd_run(Args args) {
  std::optional<std::string> input, out;
  unsigned threads = 0;  // 0: the sequential kernel
  bool validate = false;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(kRunUsage, stdout);
      return 0;
    }
    if (args.option("--threads", true)) {
      const std::uint64_t n = parse_count_option(args, "--threads", args.value());
      if (n > 4096) usage_error(kRunUsage, "--threads " + args.value() + ": expected at most 4096");
      threads = n == 0 ? std::max(1u, std::thread::hardware_concurrency()) : static_cast<unsigned>(n);
    } else if (args.option("--out", true)) {
      out = args.value();
    } else if (args.option("--validate", false)) {
      validate = true;
    } else if (args.peek().size() > 1 && args.peek()[0] == '-') {
      usage_error(kRunUsage, "unknown option '" + args.peek() + "' for 'run'");
    } else if (input) {
      usage_error(kRunUsage, "run takes one input file; got '" + *input + "' and '" + args.peek() + "'");
    } else {
      input = args.next();
    }
  }
  if (!input) usage_error(kRunUsage, "run needs an input file");
  enum class OutKind { none, tetgen, vtu } out_kind = OutKind::none;
  if (out) {
    // Decide before the (possibly long) run, so a typo cannot waste it.
    if (ends_with_nocase(*out, ".node") || ends_with_nocase(*out, ".ele")) out_kind = OutKind::tetgen;
    else if (ends_with_nocase(*out, ".vtu")) out_kind = OutKind::vtu;
    else usage_error(kRunUsage, "--out " + *out + ": expected a name ending in .node (TetGen) or .vtu (VTK)");
  }

  pdt::support::Stopwatch read_sw;
  pdt::OpStream s;
  if (is_point_file(*input)) {
    const std::vector<pdt::Point3> pts = pdt::read_points(*input);
    s.ops.resize(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) s.ops[i].point = pts[i];
  } else {
    s = pdt::read_ops(*input);
  }
  const double read_seconds = read_sw.seconds();

  pdt::Triangulation t;
  const ReplayStats st = threads ? replay_engine(s, threads, t) : replay(s, t);

  row("input", *input + (s.box ? ", box " + box_string(*s.box) : ""));
  row("threads", st.engine ? std::to_string(st.threads_used) + " (parallel engine, " +
                                 std::to_string(st.blocks_per_axis) + "^3 blocks, allocator " +
                                 pdt::allocator_name() + ")"
                           : std::string("1 (sequential kernel)"));
  row("vertices", format_count(t.number_of_vertices()));
  row("finite tets", format_count(t.number_of_finite_cells()));
  row("insertions", format_count(st.insertions) + " (" + format_count(st.duplicates) + " duplicates)");
  row("removals", format_count(st.removals) +
                      (st.multiplicity_lowered ? " (" + format_count(st.multiplicity_lowered) + " lowered a multiplicity)" : ""));
  row("read time", format_seconds(read_seconds));
  if (st.mixed_seconds > 0) {
    row("mixed time", format_seconds(st.mixed_seconds) + " (insertions and removals interleaved)");
  } else {
    row("insert time", format_seconds(st.insert_seconds) + per_second(st.insertions, st.insert_seconds));
    row("remove time", format_seconds(st.remove_seconds) + per_second(st.removals, st.remove_seconds));
  }
  const double total = st.insert_seconds + st.remove_seconds + st.mixed_seconds;
  row("operations/s", total > 0 ? format_count(static_cast<std::uint64_t>(static_cast<double>(s.ops.size()) / total))
                                : std::string("n/a"));
  row("peak memory", format_megabytes(pdt::support::peak_rss_bytes()));
  if (st.engine) {
    const pdt::WorkerStats w = st.engine_stats.total();
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s completed, %s attempts, %s rollbacks, %s deferred, %s sleeps (%.3f s asleep)",
                  format_count(w.completed).c_str(), format_count(w.attempts).c_str(),
                  format_count(w.rollbacks).c_str(), format_count(w.deferred).c_str(), format_count(w.sleeps).c_str(),
                  w.seconds_asleep);
    row("workers", buf);
    std::snprintf(buf, sizeof buf, "%.4f%% (max over workers); %s operations ran with the world stopped",
                  100.0 * w.max_rollbacks_per_completed, format_count(st.engine_stats.global_operations).c_str());
    row("rollbacks/op", buf);
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
    const pdt::Mesh m = pdt::extract_mesh(t);
    if (out_kind == OutKind::tetgen) pdt::write_tetgen(*out, m);
    else pdt::write_vtu(*out, m);
    row("wrote", *out + " (" + format_count(m.points.size()) + " points, " + format_count(m.tets.size()) + " tets)");
  }
  std::fflush(stdout);
  return status;
}

// ---- check -----------------------------------------------------------------------

int cmd_check(Args args) {
  std::optional<std::string> input;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(kCheckUsage, stdout);
      return 0;
    }
    if (args.peek().size() > 1 && args.peek()[0] == '-') usage_error(kCheckUsage, "unknown option '" + args.peek() + "' for 'check'");
    if (input) usage_error(kCheckUsage, "check takes one mesh; got '" + *input + "' and '" + args.peek() + "'");
    input = args.next();
  }
  if (!input) usage_error(kCheckUsage, "check needs a mesh file (MESH.node)");
  const pdt::Mesh m = pdt::read_tetgen(*input);
  const pdt::MeshCheck c = pdt::check_mesh(m);
  std::printf("%s: %s%s\n", input->c_str(), c.valid ? "" : "INVALID: ", c.message.c_str());
  return c.valid ? 0 : 1;
}

int dispatch(int argc, char** argv) {
  std::vector<std::string> a(argv + 1, argv + argc);
  if (a.empty()) usage_error(kMainUsage, "no command given");
  const std::string cmd = a[0];
  a.erase(a.begin());
  if (is_help(cmd) || cmd == "help") {
    if (!a.empty() && a[0] == "gen") std::fputs(kGenUsage, stdout);
    else if (!a.empty() && a[0] == "run") std::fputs(kRunUsage, stdout);
    else if (!a.empty() && a[0] == "check") std::fputs(kCheckUsage, stdout);
    else std::fputs(kMainUsage, stdout);
    return 0;
  }
  if (cmd == "gen") return cmd_gen(Args(std::move(a), kGenUsage));
  if (cmd == "run") return cmd_run(Args(std::move(a), kRunUsage));
  if (cmd == "check") return cmd_check(Args(std::move(a), kCheckUsage));
  usage_error(kMainUsage, "unknown command '" + cmd + "'");
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const int status = dispatch(argc, argv);
    // A summary lost to a full disk or a closed pipe is a failure too.
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
      std::fprintf(stderr, "pdt: cannot write to standard output: %s\n", std::strerror(errno));
      return 2;
    }
    return status;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "pdt: %s\n\n%s", e.message.c_str(), e.usage);
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "pdt: %s\n", e.what());
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "pdt: out of memory\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pdt: internal error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "pdt: internal error (unknown exception)\n");
  }
  return 2;
}
