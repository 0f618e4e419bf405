// SPDX-License-Identifier: MIT
// pdt gen: writes a synthetic operation stream.
#include <unistd.h>

#include <cstdio>
#include <new>
#include <optional>
#include <string>

#include "cli.hpp"
#include "pdt/pdt.hpp"
#include "support/sys_info.hpp"

namespace pdt_cli {

using pdt::support::format_count;
using pdt::support::format_seconds;

const char* const gen_usage =
    "usage: pdt gen --points N --out FILE.ops|FILE.opsb [options]\n"
    "\n"
    "Writes a synthetic operation stream: N insertions, then (or interleaved\n"
    "with them) the removal of the first floor(F*N) inserted points.\n"
    "\n"
    "options:\n"
    "  --dist D               uniform (default), normal, line, grid, sphere, corner, kuzmin,\n"
    "                         front_x, front_y, front_z, clusters (generate.hpp says what each is)\n"
    "  --points N             number of insertions (e.g. 1000000 or 1e6)\n"
    "  --remove-fraction F    fraction in [0, 1] of the insertions to undo (default 0)\n"
    "  --interleaved          put each removal soon after its insertion (default: all at the end)\n"
    "  --seed S               random seed (default 1); same seed, same stream, on any platform\n"
    "  --out FILE             .opsb writes the binary form, anything else text\n";


int cmd_gen(Args args) {
  pdt::GenerateOptions o;
  std::optional<std::string> out;
  bool have_points = false;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(gen_usage, stdout);
      return 0;
    }
    if (args.option("--dist", true)) {
      try {
        o.dist = pdt::parse_distribution(args.value());
      } catch (const pdt::Error& e) {
        usage_error(gen_usage, e.what());
      }
    } else if (args.option("--points", true)) {
      o.points = parse_count_option(args, "--points", args.value(), pdt::GenerateOptions::max_points);
      have_points = true;
    } else if (args.option("--remove-fraction", true)) {
      o.remove_fraction = parse_real_option(args, "--remove-fraction", args.value());
      if (!(o.remove_fraction >= 0 && o.remove_fraction <= 1))
        usage_error(gen_usage, "--remove-fraction " + args.value() + ": expected a number in [0, 1]");
    } else if (args.option("--interleaved", false)) {
      o.removal_order = pdt::RemovalOrder::interleaved;
    } else if (args.option("--seed", true)) {
      o.seed = parse_count_option(args, "--seed", args.value());
    } else if (args.option("--out", true)) {
      out = args.value();
    } else {
      usage_error(gen_usage, "unknown option '" + args.peek() + "' for 'gen'");
    }
  }
  if (!have_points) usage_error(gen_usage, "gen needs --points N");
  if (!out || out->empty()) usage_error(gen_usage, "gen needs --out FILE");
  require_stream_output_name(gen_usage, "--out", *out);
  // The stream is made in memory before it is written: the points, then the
  // operations. More than the machine has is refused before it starts (else
  // the system would stop it part way, or it would fail with no word of why).
  const double ops = static_cast<double>(o.points) * (1 + o.remove_fraction);
  const double need = static_cast<double>(o.points) * sizeof(pdt::Point3) + ops * sizeof(pdt::Operation);
  const double have = static_cast<double>(::sysconf(_SC_PHYS_PAGES)) * static_cast<double>(::sysconf(_SC_PAGE_SIZE));
  auto too_large = [&](const std::string& why) {
    const double per_point = need / static_cast<double>(o.points);
    throw pdt::Error(pdt::ErrorCode::invalid_argument,
                     "--points " + format_count(o.points) + ": gen makes the whole stream in memory before writing it, " +
                         pdt::support::format_megabytes(static_cast<std::uint64_t>(need)) + " for this one (" +
                         std::to_string(static_cast<int>(per_point)) + " bytes a point), " + why +
                         "; give fewer points (half this machine's memory holds about " +
                         format_count(static_cast<std::uint64_t>(have / per_point / 2)) + ")");
  };
  if (have > 0 && need > have)
    too_large("more than this machine's " + pdt::support::format_megabytes(static_cast<std::uint64_t>(have)));
  pdt::support::Stopwatch sw;
  pdt::OpStream s;
  try {
    s = pdt::generate(o);
  } catch (const std::bad_alloc&) {
    too_large("and it did not fit in the memory free");
  }
  pdt::write_ops(*out, s);
  outputs_in_place(*out);
  std::fprintf(summary_stream(), "wrote %s: %s insertions, %s removals (%s, seed %llu), box %s, in %s\n", out->c_str(),
              format_count(s.insert_count()).c_str(), format_count(s.remove_count()).c_str(), pdt::to_string(o.dist),
              static_cast<unsigned long long>(o.seed), box_string(*s.box).c_str(), format_seconds(sw.seconds()).c_str());
  return 0;
}

}  // namespace pdt_cli
