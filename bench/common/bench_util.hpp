// SPDX-License-Identifier: MIT
#pragma once
// Shared by the benches: command-line options, the points of an experiment,
// the machine's description, progress lines on stderr.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "pdt/generate.hpp"
#include "pdt/geometry.hpp"
#include "pdt/ops.hpp"

namespace pdt_bench {

// Options "--name value" (and flags "--name"), each bound to a variable; usage
// text generated from the help strings; --help prints it. A bad value or an
// unknown option prints the usage and exits 2.
class ArgParser {
 public:
  ArgParser(std::string program, std::string summary) : program_(std::move(program)), summary_(std::move(summary)) {}
  void flag(const char* name, const char* help, bool& out);
  void count(const char* name, const char* help, std::uint64_t& out, std::uint64_t min = 0);
  void real(const char* name, const char* help, double& out, double min, double max);
  void text(const char* name, const char* help, std::string& out);
  void list(const char* name, const char* help, std::vector<std::string>& out);
  void counts(const char* name, const char* help, std::vector<unsigned>& out, unsigned min, unsigned max);
  void parse(int argc, char** argv);

 private:
  struct Opt {
    std::string name, help;
    bool takes_value;
    std::function<bool(const std::string&)> set;  // false: bad value
  };
  [[noreturn]] void usage(int code) const;
  std::string program_, summary_;
  std::vector<Opt> opts_;
};

std::vector<std::string> split(const std::string& s, char sep = ',');
std::vector<pdt::Distribution> distributions(const std::vector<std::string>& names);  // exits 2 on a bad name

// The inserted points of a stream, in order.
std::vector<pdt::Point3> points_of(const pdt::OpStream& s);
// pdt::generate's points of one distribution (random order) and their box.
struct PointSet {
  std::vector<pdt::Point3> points;
  pdt::Box box;
};
PointSet generated_points(pdt::Distribution dist, std::uint64_t n, std::uint64_t seed);

// For each of the first n_remove insertions: does undoing it make the vertex
// disappear (the last undone insertion of its point)? CGAL has no multiplicity.
std::vector<char> last_removals(const std::vector<pdt::Point3>& pts, std::size_t n_remove);

// Returns freed heap to the OS (malloc_trim) so the next configuration starts clean.
void settle();
double mib(double bytes);
std::string cpu_model();
int affinity_cpus();  // CPUs this process may run on; 0 if unknown
// A line on stderr, flushed (progress of a long bench).
void progress(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

struct PointHash {
  std::size_t operator()(const pdt::Point3& p) const;
};

}  // namespace pdt_bench
