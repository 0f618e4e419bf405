// SPDX-License-Identifier: MIT
#pragma once
// Running the `pdt` tool as a separate process from a test: exit status and
// captured output.
#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "common/io_test_util.hpp"

namespace pdt_test {

struct Result {
  int code = -1;  // exit status, or -1 if the tool did not exit normally (crash)
  std::string out, err;
};

inline bool have_tool() {
#ifdef PDT_TOOL_PATH
  if (std::filesystem::exists(PDT_TOOL_PATH)) return true;
  WARN("pdt tool not found at " << PDT_TOOL_PATH << "; skipping");
#else
  WARN("PDT_TOOL_PATH not defined; skipping");
#endif
  return false;
}

// Runs `pdt <args>` with stdout and stderr captured in files of d.
// piped_stdin: a file piped to the tool's standard input (through cat, so
// that the tool sees a pipe, not a file); "" = /dev/null.
inline Result run_pdt(const TempDir& d, const std::string& args, const std::string& piped_stdin = "") {
  Result r;
#ifdef PDT_TOOL_PATH
  const std::string out = d.file("stdout.txt"), err = d.file("stderr.txt");
  const std::string tool = std::string("'") + PDT_TOOL_PATH + "' " + args + " >'" + out + "' 2>'" + err + "'";
  const std::string cmd = piped_stdin.empty() ? tool + " </dev/null" : "cat '" + piped_stdin + "' | " + tool;
  const int status = std::system(cmd.c_str());
  r.code = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : -1;
  r.out = pdt_test::read_file(out);
  r.err = pdt_test::read_file(err);
#else
  (void)d;
  (void)args;
  (void)piped_stdin;
#endif
  return r;
}

}  // namespace pdt_test
