// SPDX-License-Identifier: MIT
#include "cli.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <thread>

#include "pdt/engine_options.hpp"
#include "pdt/error.hpp"
#include "pdt/io.hpp"
#include "support/cli_text.hpp"
#include "support/sys_info.hpp"

namespace pdt_cli {

namespace {
// Standard output, or standard error once an output of the command was found
// to be written to standard output (require_stream_output_name).
std::FILE* summary_file = stdout;
}  // namespace

void usage_error(const char* usage, std::string msg) { throw UsageError{std::move(msg), usage}; }

bool is_help(const std::string& a) { return a == "--help" || a == "-h"; }

void require_writable_dir(const char* option, const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  struct stat st;
  int err = 0;
  if (::stat(dir.c_str(), &st) != 0) err = errno;
  else if (!S_ISDIR(st.st_mode)) err = ENOTDIR;
  else if (::access(dir.c_str(), W_OK) != 0) err = errno;
  if (err)
    throw pdt::Error(pdt::ErrorCode::io_failure, std::string(option) + " " + path + ": cannot write in '" + dir +
                                                     "': " + std::strerror(err));
}

namespace {
// What path names when it is a symbolic link to a file not there yet,
// through a chain of such links (where the writers make the file:
// OutputFile), each relative link read from its own folder; "" otherwise (a
// chain that loops or runs past 40 links too: opening it fails anyway).
std::string dangling_link_target(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) == 0) return "";
  std::string at = path;
  for (int hop = 0; hop < 40; ++hop) {
    if (::lstat(at.c_str(), &st) != 0) return hop == 0 ? "" : at;  // the missing file at the chain's end
    if (!S_ISLNK(st.st_mode)) return "";
    std::string link(4096, '\0');
    const ssize_t n = ::readlink(at.c_str(), link.data(), link.size());
    if (n <= 0) return "";
    link.resize(static_cast<std::size_t>(n));
    at = link[0] == '/' ? link : at.substr(0, at.find_last_of('/') + 1) + link;
  }
  return "";
}
}  // namespace

void require_writable_file(const char* option, const std::string& path) {
  struct stat st;
  const bool exists = ::stat(path.c_str(), &st) == 0;
  // A name that cannot be looked up for another reason than a missing file
  // or folder (a loop of symbolic links, a name too long) fails the same way
  // when the output is opened: refused now, before the run.
  if (const int err = exists ? 0 : errno; err != 0 && err != ENOENT && err != ENOTDIR)
    throw pdt::Error(pdt::ErrorCode::io_failure,
                     std::string(option) + ": cannot write '" + path + "': " + std::strerror(err));
  if (exists) {
    if (S_ISDIR(st.st_mode))
      throw pdt::Error(pdt::ErrorCode::io_failure,
                       std::string(option) + ": cannot write '" + path + "': it is a directory");
    if (!S_ISREG(st.st_mode)) return;  // a device or FIFO: written in place, nothing made in its directory
    // A file that may not be written is not replaced either (OutputFile).
    if (::access(path.c_str(), W_OK) != 0)
      throw pdt::Error(pdt::ErrorCode::io_failure,
                       std::string(option) + ": cannot write '" + path + "': " + std::strerror(errno));
  } else if (const std::string link = dangling_link_target(path); !link.empty()) {
    // A link to a file not there yet: the file is made where the link points.
    require_writable_dir(option, link);
    return;
  }
  // /dev/stdout, /dev/fd/N, /proc/self/fd/N: written in place too
  // (OutputFile), nothing made in their folder. One that is not there would
  // be made there like any other file: its folder is checked.
  if (exists && (path.rfind("/dev/", 0) == 0 || path.rfind("/proc/", 0) == 0)) return;
  require_writable_dir(option, path);
}

std::vector<std::string> mesh_output_files(const std::string& out) {
  // The writers' own rule (write_tetgen, write_vtu), checked before the run.
  const std::string base = out.substr(out.find_last_of('/') + 1);
  const bool vtu = pdt::support::ends_with_nocase(out, ".vtu");
  const std::string node = pdt::tetgen_files(base).node;  // ".node" or ".NODE": no name before it
  if (base.empty() || (!vtu && node.size() == 5 && pdt::support::ends_with_nocase(node, ".node")))
    throw pdt::Error(pdt::ErrorCode::invalid_argument,
                     "--out " + out + ": names no file (give it a name such as mesh.vtu or mesh.node)");
  if (vtu) return {out};
  const pdt::TetgenFiles files = pdt::tetgen_files(out);
  return {files.node, files.ele};
}

bool is_point_file(const std::string& p) {
  for (const char* ext : {".xyz", ".xyz.gz", ".ply", ".off", ".node", ".smesh"})
    if (pdt::support::ends_with_nocase(p, ext)) return true;
  return false;
}

void require_stream_output_name(const char* usage, const char* option, const std::string& path) {
  if (pdt::support::ends_with_nocase(path, ".gz"))
    usage_error(usage, std::string(option) + " " + path +
                           ": pdt writes streams uncompressed (it reads them gzipped); name it FILE.ops or FILE.opsb "
                           "and gzip it afterwards");
  if (is_point_file(path))
    usage_error(usage, std::string(option) + " " + path +
                           ": pdt run reads a file of that extension as a point set, not as an operation stream; "
                           "name it FILE.ops (text) or FILE.opsb (binary)");
  for (const char* mesh_ext : {".vtu", ".ele"})
    if (pdt::support::ends_with_nocase(path, mesh_ext))
      usage_error(usage, std::string(option) + " " + path + ": a " + mesh_ext +
                             " name is for a mesh, and this writes an operation stream; name it FILE.ops (text) or "
                             "FILE.opsb (binary)");
  require_writable_file(option, path);
  // pdt gen --out /dev/stdout > FILE: the stream goes to standard output, the
  // summary to standard error, so that FILE holds the stream alone.
  if (writes_standard_output(path)) summary_file = stderr;
}

bool same_file(const std::string& a, const std::string& b) {
  // Both exist: the same file whatever the names (a hard link, /dev/fd/N).
  struct stat sa, sb;
  if (::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0)
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  // Else by where they will be written: a link to a file not there yet names
  // its target (the writers make the file there).
  const std::string la = dangling_link_target(a), lb = dangling_link_target(b);
  const std::string& wa = la.empty() ? a : la;
  const std::string& wb = lb.empty() ? b : lb;
  // Made absolute first: weakly_canonical leaves a bare name ("m.vtu", no
  // part of it there yet) relative, and "./m.vtu" absolute.
  std::error_code ea, eb;
  std::filesystem::path pa = std::filesystem::absolute(wa, ea), pb = std::filesystem::absolute(wb, eb);
  if (!ea) pa = std::filesystem::weakly_canonical(pa, ea);
  if (!eb) pb = std::filesystem::weakly_canonical(pb, eb);
  return ea || eb ? wa == wb : pa == pb;
}

bool Args::option(const char* name, bool takes_value) {
  const std::string& a = a_[i_];
  const std::size_t n = std::strlen(name);
  if (a.compare(0, n, name) != 0) return false;
  if (a.size() != n && a[n] != '=') return false;
  if (std::find(seen_.begin(), seen_.end(), name) != seen_.end())
    usage_error(usage_, std::string("option ") + name + " is given twice: give it once");
  seen_.emplace_back(name);
  if (a.size() == n) {
    ++i_;
    if (takes_value) {
      if (done()) usage_error(usage_, std::string("option ") + name + " needs a value");
      // "--domain --size 0.2": the value was forgotten, not "--size".
      if (a_[i_].compare(0, 2, "--") == 0)
        usage_error(usage_, std::string("option ") + name + " needs a value, not the option '" + a_[i_] +
                                "' (a value that starts with -- goes as " + name + "=VALUE)");
      value_ = a_[i_++];
    }
    return true;
  }
  if (!takes_value) usage_error(usage_, std::string("option ") + name + " takes no value");
  value_ = a.substr(n + 1);
  ++i_;
  return true;
}

unsigned parse_workers_option(const Args& args, const std::string& v) {
  const std::uint64_t n = parse_count_option(args, "--threads", v, pdt::EngineOptions::max_workers);
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  if (n == 0) return cores;
  constexpr unsigned max_per_core = 16;
  if (n > std::uint64_t{max_per_core} * cores)
    std::fprintf(stderr,
                 "pdt: note: --threads %llu on %u hardware threads: workers beyond about %u per hardware thread "
                 "make the run slower, not faster (idle workers search each other's blocks for work); "
                 "--threads 0 gives one per hardware thread\n",
                 static_cast<unsigned long long>(n), cores, max_per_core);
  return static_cast<unsigned>(n);
}

std::uint64_t parse_count_option(const Args& args, const char* name, const std::string& v, std::uint64_t max) {
  auto too_large = [&] {
    usage_error(args.usage(), std::string(name) + " '" + v + "': too large (at most " + std::to_string(max) + ")");
  };
  unsigned long long n = 0;
  if (pdt::support::parse_count(v, n)) {
    if (n > max) too_large();
    return n;
  }
  double d = 0;
  if (pdt::support::parse_real(v, d) && !std::signbit(d) && d == std::floor(d)) {
    if (d >= 0x1p64 || d > static_cast<double>(max)) too_large();  // the limit first: it holds in digits too
    usage_error(args.usage(), std::string(name) + " '" + v +
                                  "': with a decimal point or an exponent at most 2^53 (9007199254740992); "
                                  "write larger counts in digits");
  }
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
  const double lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
  std::string s;
  for (int a = 0; a < 3; ++a) {
    s += a ? "] x [" : "[";
    s += format_double(lo[a]);
    s += ", ";
    s += format_double(hi[a]);
  }
  s += "]";
  return s;
}

std::FILE* summary_stream() { return summary_file; }

void peak_memory_row(std::uint64_t run_peak, const char* then) {
  // The peak read again later cannot be lower; the kernel's count can
  // read a little lower, once some pages moved between its counters.
  row("peak memory", pdt::support::format_megabytes(run_peak) +
                         (then ? ", " + pdt::support::format_megabytes(std::max(run_peak, pdt::support::peak_rss_bytes())) + then
                               : std::string()));
}

void require_summary_written() {
  errno = 0;
  if (std::fflush(summary_file) == 0 && !std::ferror(summary_file)) return;
  const int err = errno != 0 ? errno : EIO;
  throw pdt::Error(pdt::ErrorCode::io_failure,
                   std::string("cannot write the summary to standard ") + (summary_file == stderr ? "error" : "output") +
                       ": " + std::strerror(err) + "; the output files were not written (older ones stay as they were)");
}

namespace {
std::string placed_outputs;
}
void outputs_in_place(const std::string& names) {
  if (!placed_outputs.empty()) placed_outputs += ", ";
  placed_outputs += names;
}
const std::string& outputs_placed() { return placed_outputs; }

bool writes_standard_output(const std::string& path) {
  struct stat out, st;
  if (::fstat(STDOUT_FILENO, &out) != 0 || ::stat(path.c_str(), &st) != 0) return false;
  if (out.st_dev != st.st_dev || out.st_ino != st.st_ino) return false;
  // Both /dev/null (or another device that is not a terminal): nothing to mix up.
  return !S_ISCHR(out.st_mode) || ::isatty(STDOUT_FILENO) == 1;
}

void row(const char* key, const std::string& value) { std::fprintf(summary_file, "%-16s %s\n", key, value.c_str()); }

std::string per_second(std::uint64_t n, double s) {
  if (n == 0 || s <= 0) return "";
  return " (" + pdt::support::format_count(static_cast<std::uint64_t>(static_cast<double>(n) / s)) + "/s)";
}

}  // namespace pdt_cli
