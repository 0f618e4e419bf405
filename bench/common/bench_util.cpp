// SPDX-License-Identifier: MIT
#include "common/bench_util.hpp"

#include <malloc.h>
#include <sched.h>

#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <unordered_map>

#include "pdt/error.hpp"
#include "support/cli_text.hpp"

namespace pdt_bench {

void ArgParser::flag(const char* name, const char* help, bool& out) {
  opts_.push_back({name, help, false, [&out](const std::string&) {
                     out = true;
                     return true;
                   }});
}

void ArgParser::count(const char* name, const char* help, std::uint64_t& out, std::uint64_t min) {
  opts_.push_back({name, help, true, [&out, min](const std::string& v) {
                     unsigned long long x = 0;
                     if (!pdt::support::parse_count(v, x) || x < min) return false;
                     out = x;
                     return true;
                   }});
}

void ArgParser::real(const char* name, const char* help, double& out, double min, double max) {
  opts_.push_back({name, help, true, [&out, min, max](const std::string& v) {
                     double x = 0;
                     if (!pdt::support::parse_real(v, x) || !(x >= min && x <= max)) return false;
                     out = x;
                     return true;
                   }});
}

void ArgParser::text(const char* name, const char* help, std::string& out) {
  opts_.push_back({name, help, true, [&out](const std::string& v) {
                     out = v;
                     return true;
                   }});
}

void ArgParser::list(const char* name, const char* help, std::vector<std::string>& out) {
  opts_.push_back({name, help, true, [&out](const std::string& v) {
                     out = split(v);
                     return !out.empty();
                   }});
}

void ArgParser::counts(const char* name, const char* help, std::vector<unsigned>& out, unsigned min, unsigned max) {
  opts_.push_back({name, help, true, [&out, min, max](const std::string& v) {
                     std::vector<unsigned> got;
                     for (const std::string& item : split(v)) {
                       unsigned long long x = 0;
                       if (!pdt::support::parse_count(item, x) || x < min || x > max) return false;
                       got.push_back(static_cast<unsigned>(x));
                     }
                     if (got.empty()) return false;
                     out = got;
                     return true;
                   }});
}

void ArgParser::usage(int code) const {
  std::FILE* f = code ? stderr : stdout;
  std::fprintf(f, "usage: %s [options]\n%s\n\noptions:\n", program_.c_str(), summary_.c_str());
  for (const Opt& o : opts_)
    std::fprintf(f, "  %-22s %s\n", (o.name + (o.takes_value ? " V" : "")).c_str(), o.help.c_str());
  std::exit(code);
}

void ArgParser::parse(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") usage(0);
    const Opt* found = nullptr;
    for (const Opt& o : opts_)
      if (o.name == a) found = &o;
    if (!found) {
      std::fprintf(stderr, "%s: unknown option %s\n", program_.c_str(), a.c_str());
      usage(2);
    }
    std::string value;
    if (found->takes_value) {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s: %s needs a value\n", program_.c_str(), a.c_str());
        usage(2);
      }
      value = argv[++i];
    }
    if (!found->set(value)) {
      std::fprintf(stderr, "%s: bad value '%s' for %s\n", program_.c_str(), value.c_str(), a.c_str());
      usage(2);
    }
  }
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep))
    if (!item.empty()) out.push_back(item);
  return out;
}

std::vector<pdt::Distribution> distributions(const std::vector<std::string>& names) {
  std::vector<pdt::Distribution> out;
  try {
    for (const auto& d : names) out.push_back(pdt::parse_distribution(d));
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "%s\n", e.what());
    std::exit(2);
  }
  return out;
}

std::vector<pdt::Point3> points_of(const pdt::OpStream& s) {
  std::vector<pdt::Point3> pts;
  pts.reserve(s.ops.size());
  for (const auto& op : s.ops)
    if (op.kind == pdt::Operation::Kind::insert) pts.push_back(op.point);
  return pts;
}

PointSet generated_points(pdt::Distribution dist, std::uint64_t n, std::uint64_t seed) {
  pdt::GenerateOptions g;
  g.dist = dist;
  g.points = n;
  g.seed = seed;
  const pdt::OpStream s = pdt::generate(g);
  return {points_of(s), *s.box};
}

std::vector<char> last_removals(const std::vector<pdt::Point3>& pts, std::size_t n_remove) {
  std::vector<char> out(n_remove, 0);
  std::unordered_map<pdt::Point3, std::uint32_t, PointHash> count;
  count.reserve(pts.size() * 2);
  for (const auto& p : pts) ++count[p];
  for (std::size_t k = 0; k < n_remove; ++k) out[k] = --count[pts[k]] == 0;
  return out;
}

void settle() { ::malloc_trim(0); }
double mib(double bytes) { return bytes / (1024.0 * 1024.0); }

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) {
      auto colon = line.find(':');
      if (colon != std::string::npos) {
        std::string m = line.substr(colon + 1);
        m.erase(0, m.find_first_not_of(" \t"));
        return m;
      }
    }
  return "unknown";
}

int affinity_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (::sched_getaffinity(0, sizeof set, &set) != 0) return 0;
  return CPU_COUNT(&set);
}

void progress(const char* fmt, ...) {
  std::fflush(stdout);  // what was printed before comes first when both go to one file
  va_list ap;
  va_start(ap, fmt);
  std::vfprintf(stderr, fmt, ap);
  va_end(ap);
  std::fflush(stderr);
}

std::size_t PointHash::operator()(const pdt::Point3& p) const {
  std::size_t h = std::hash<double>()(p.x + 0.0);
  h ^= std::hash<double>()(p.y + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
  h ^= std::hash<double>()(p.z + 0.0) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
  return h;
}

}  // namespace pdt_bench
