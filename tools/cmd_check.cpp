// SPDX-License-Identifier: MIT
// pdt check: is a TetGen mesh a Delaunay tetrahedralization?
#include <cstdio>
#include <optional>
#include <string>

#include "cli.hpp"
#include "pdt/pdt.hpp"
#include "support/cli_text.hpp"

namespace pdt_cli {

const char* const check_usage =
    "usage: pdt check MESH.node\n"
    "\n"
    "Reads a TetGen mesh (MESH.node and MESH.ele) and checks, with exact\n"
    "predicates, that it is a Delaunay tetrahedralization of its points.\n"
    "Exit status: 0 valid, 1 invalid, 2 error.\n";


int cmd_check(Args args) {
  std::optional<std::string> input;
  while (!args.done()) {
    if (is_help(args.peek())) {
      std::fputs(check_usage, stdout);
      return 0;
    }
    if (args.peek().size() > 1 && args.peek()[0] == '-') usage_error(check_usage, "unknown option '" + args.peek() + "' for 'check'");
    if (input) usage_error(check_usage, "check takes one mesh; got '" + *input + "' and '" + args.peek() + "'");
    input = args.next();
  }
  if (!input) usage_error(check_usage, "check needs a mesh file (MESH.node)");
  for (const char* ext : {".vtu", ".ops", ".opsb", ".xyz", ".ply", ".off", ".smesh", ".gz"})
    if (pdt::support::ends_with_nocase(*input, ext))
      usage_error(check_usage, *input + ": check reads a TetGen mesh (MESH.node beside MESH.ele); write one with "
                                        "pdt run or pdt refine --out MESH.node");
  const pdt::Mesh m = pdt::read_tetgen(*input);
  const pdt::MeshCheck c = pdt::check_mesh(m);
  std::printf("%s: %s%s\n", input->c_str(), c.valid ? "" : "INVALID: ", c.message.c_str());
  return c.valid ? 0 : 1;
}

}  // namespace pdt_cli
