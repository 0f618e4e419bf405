// SPDX-License-Identifier: MIT
#pragma once
// The pdt tool's command-line plumbing, shared by its commands: options of
// the form "--name value" or "--name=value", usage errors (exit 2 with the
// command's usage), number options, and the summary's rows.
#include <cstdio>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "pdt/geometry.hpp"

namespace pdt_cli {

// A command-line mistake: reported with the command's usage, exit 2.
struct UsageError {
  std::string message;
  const char* usage;
};

[[noreturn]] void usage_error(const char* usage, std::string msg);
bool is_help(const std::string& a);

class Args {
 public:
  Args(std::vector<std::string> a, const char* usage) : a_(std::move(a)), usage_(usage) {}
  bool done() const { return i_ >= a_.size(); }
  const std::string& peek() const { return a_[i_]; }
  std::string next() { return a_[i_++]; }
  // If the current argument is option `name`, consumes it and returns true;
  // the value (for options that take one) is then in value(). An option given
  // a second time is a usage error ("--size 0.3 --size 0.2": which one was
  // meant is not ours to guess).
  bool option(const char* name, bool takes_value);
  const std::string& value() const { return value_; }
  const char* usage() const { return usage_; }

 private:
  std::vector<std::string> a_;
  std::size_t i_ = 0;
  std::string value_;
  const char* usage_;
  std::vector<std::string> seen_;  // the options consumed so far, each once
};

// A non-negative integer option value: "1000000", or "1e6" when integral, at
// most `max` (a larger one, or one past 2^64, is refused naming `max`).
std::uint64_t parse_count_option(const Args& args, const char* name, const std::string& v,
                                 std::uint64_t max = std::numeric_limits<std::uint64_t>::max());
double parse_real_option(const Args& args, const char* name, const std::string& v);
// --threads N: the engine's workers, 0 = one per hardware thread. Far more
// workers than hardware threads (over 16 each) is allowed but slow (an idle
// worker looks through the other workers' blocks for work, so the cost of
// finding work grows with the workers): says so on stderr.
unsigned parse_workers_option(const Args& args, const std::string& v);

// Refuses, before a long run, an output path whose directory is missing or
// not writable (pdt::Error io_failure naming the option and the path); the
// write itself may still fail later (a full disk), and says so then.
void require_writable_dir(const char* option, const std::string& path);
// The path is not a directory, and require_writable_dir unless it is written
// in place (an existing device or FIFO, or a name under /dev or /proc).
void require_writable_file(const char* option, const std::string& path);
// The files a mesh output writes: FILE.vtu itself, or TetGen's .node and .ele
// pair for a name ending in .node or .ele (pdt::tetgen_files). A name that
// names no file ("", a folder, ".node") is refused (pdt::Error invalid_argument).
std::vector<std::string> mesh_output_files(const std::string& out);
// An operation stream's output name: refused (usage) if it ends in .gz, since
// pdt writes streams uncompressed (and reads them gzipped), or in an
// extension pdt run reads as a point file (is_point_file), since it could not
// be replayed; then require_writable_file. When the path is this process's
// standard output (writes_standard_output), the command's summary goes to
// standard error from then on.
void require_stream_output_name(const char* usage, const char* option, const std::string& path);
// The point-file extensions pdt run reads as a point set (.xyz, .xyz.gz, .ply,
// .off, .node, .smesh); anything else is an operation stream.
bool is_point_file(const std::string& path);
// a and b name the same file: the same device and inode when both exist, else
// the same path resolved as far as it exists, a link to a file not there yet
// standing for its target (else compared as given).
bool same_file(const std::string& a, const std::string& b);

std::string box_string(const pdt::Box& b);
// path is the file this process's standard output writes (/dev/stdout, or the
// file stdout is redirected to), other than /dev/null-like devices.
bool writes_standard_output(const std::string& path);
// Where a command's summary goes: standard output, or standard error when an
// output stream of the command goes to standard output.
std::FILE* summary_stream();
// Flushes summary_stream(); throws pdt::Error(io_failure) if what was printed
// could not be written (a command calls it before it puts its outputs in
// place, so that a lost summary fails the run with the files as they were).
void require_summary_written();
// The outputs a command has put in place (names, for the message when the
// summary's last lines, written after them, are lost: `pdt run ... | head -1`).
void outputs_in_place(const std::string& names);
const std::string& outputs_placed();
// One "key   value" line of a command's summary (on summary_stream()).
void row(const char* key, const std::string& value);
// The "peak memory" row: the run's own peak (taken before its outputs were
// written), then, when `then` names what came after (" with writing the
// mesh"), the process's peak now.
void peak_memory_row(std::uint64_t run_peak, const char* then);
// " (12,345/s)", or "" when there is nothing to say.
std::string per_second(std::uint64_t n, double s);

// The commands (each in its cmd_<name>.cpp), with their usage texts.
extern const char* const gen_usage;
extern const char* const run_usage;
extern const char* const check_usage;
extern const char* const refine_usage;
int cmd_gen(Args args);
int cmd_run(Args args);
int cmd_check(Args args);
int cmd_refine(Args args);

}  // namespace pdt_cli
