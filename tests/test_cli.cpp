// SPDX-License-Identifier: MIT
// The `pdt` command-line tool, run as a separate process: exit codes, and
// error messages naming file and line on stderr, for bad inputs and usage.
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>

#include "common/io_test_util.hpp"
#include "common/tool_run.hpp"
#include "pdt/ops.hpp"

using pdt_test::have_tool;
using pdt_test::Result;
using pdt_test::run_pdt;
using pdt_test::TempDir;
using pdt_test::write_file;

namespace {

// A bad input: exit 2 and one "pdt: <file>:<line>: ..." message on stderr.
void expect_input_error(const std::string& content, int line, const std::string& what) {
  TempDir d;
  const std::string p = d.file("in.ops");
  write_file(p, content);
  const Result r = run_pdt(d, "run '" + p + "'");
  INFO("stream:\n" << content << "\nstderr: " << r.err);
  CHECK(r.code == 2);
  CHECK(r.err.rfind("pdt: " + p + ":" + std::to_string(line) + ": ", 0) == 0);
  CHECK(r.err.find(what) != std::string::npos);
  CHECK(r.out.empty());  // no summary for a stream that was not run
}

}  // namespace

TEST_CASE("pdt rejects bad streams naming file and line, exit 2", "[cli]") {
  if (!have_tool()) return;
  SECTION("unknown verb") { expect_input_error("box 0 0 0 1 1 1\ni 0.5 0.5 0.5\nadd 1 2 3\n", 3, "unknown verb 'add'"); }
  SECTION("NaN") { expect_input_error("i 0.5 0.5 0.5\ni 0.1 nan 0.2\n", 2, "not finite"); }
  SECTION("r of an unknown insertion") { expect_input_error("i 0 0 0\ni 1 1 1\nr 0\nr 7\n", 4, "not been made yet"); }
  SECTION("r twice") { expect_input_error("i 0 0 0\nr 0\n# again\nr 0\n", 4, "already undone"); }
  SECTION("point outside the box") { expect_input_error("box 0 0 0 1 1 1\ni 0.5 0.5 2\n", 2, "outside the box"); }
  SECTION("missing field") { expect_input_error("i 0.5 0.5\n", 1, "expected 'i x y z'"); }
}

TEST_CASE("pdt reports missing files and bad usage, exit 2", "[cli]") {
  if (!have_tool()) return;
  TempDir d;
  SECTION("missing input") {
    const Result r = run_pdt(d, "run '" + d.file("missing.ops") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("pdt: cannot open '" + d.file("missing.ops") + "': No such file or directory") == 0);
  }
  SECTION("missing mesh for check") {
    const Result r = run_pdt(d, "check '" + d.file("nothing.node") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("nothing.node") != std::string::npos);
  }
  SECTION("no command") {
    const Result r = run_pdt(d, "");
    CHECK(r.code == 2);
    CHECK(r.err.find("usage: pdt") != std::string::npos);
  }
  SECTION("unknown command") {
    const Result r = run_pdt(d, "frobnicate");
    CHECK(r.code == 2);
    CHECK(r.err.find("unknown command 'frobnicate'") != std::string::npos);
    CHECK(r.err.find("usage: pdt") != std::string::npos);
  }
  SECTION("unknown option") {
    const Result r = run_pdt(d, "gen --points 10 --colour blue --out '" + d.file("x.ops") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("unknown option '--colour'") != std::string::npos);
    CHECK(r.err.find("usage: pdt gen") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(d.file("x.ops")));
  }
  SECTION("bad option values") {
    // Each refusal names the option and what to give instead.
    const std::pair<const char*, const char*> cases[] = {
        {"gen --points ten --out x.ops", "--points 'ten': expected a non-negative integer"},
        {"gen --points 10 --dist gaussian --out x.ops", "unknown distribution 'gaussian'; expected uniform, normal"},
        {"gen --points 10 --remove-fraction 2 --out x.ops", "--remove-fraction 2: expected a number in [0, 1]"},
        {"gen --points 10", "gen needs --out FILE"},
        {"gen --out x.ops", "gen needs --points N"},
        {"gen --points", "option --points needs a value"},
        {"refine --domain sphere --size 0.3 --size 0.2", "option --size is given twice: give it once"},
        {"gen --points 10 --points=20 --out x.ops", "option --points is given twice"},
        {"run a.ops --validate --validate", "option --validate is given twice"},
        {"run", "run needs an input file"},
        {"run a.ops b.ops", "run takes one input file; got 'a.ops' and 'b.ops'"},
        {"run a.ops --threads -1", "--threads '-1': expected a non-negative integer"},
        {"gen --points -0 --out x.ops", "--points '-0': expected a non-negative integer"},
        {"gen --points 1 --seed -0e0 --out x.ops", "--seed '-0e0': expected a non-negative integer"},
        {"run a.ops --out mesh.stl", "--out mesh.stl: expected a name ending in .node or .ele (TetGen's pair of files) or .vtu (VTK)"},
        {"run a.ops --vtu-ascii", "--vtu-ascii applies to a .vtu output"},
        {"run a.ops --out m.node --vtu-ascii", "--vtu-ascii applies to a .vtu output"},
        {"run a.ops --in-order", "--in-order applies to point files"},
        {"gen --points 10 --out x.ops.gz", "--out x.ops.gz: pdt writes streams uncompressed"},
        {"run a.ply.gz", "a.ply.gz: gzipped .ply files are not read"},
        {"refine --domain sphere --size 0.5 --trace t.opsb.gz", "--trace t.opsb.gz: pdt writes streams uncompressed"},
        {"check", "check needs a mesh file"},
        {"check x.vtu", "x.vtu: check reads a TetGen mesh (MESH.node beside MESH.ele)"},
        {"refine --domain --size 0.5", "option --domain needs a value, not the option '--size'"},
        {"refine --domain sphere --size 0.5 --budget 18446744073709551616",
         "--budget '18446744073709551616': too large (at most 18446744073709551615)"},
        {"refine --domain sphere --size 0.5 --trace tr.xyz",
         "--trace tr.xyz: pdt run reads a file of that extension as a point set"},
        {"gen --points 10 --out g.node", "--out g.node: pdt run reads a file of that extension as a point set"},
        {"refine --domain sphere --size 0.5 --out same.vtu --trace same.vtu",
         "--trace same.vtu: a .vtu name is for a mesh, and this writes an operation stream; name it FILE.ops"},
        {"refine --domain sphere --size 0.5 --out m.node --trace m.ele",
         "--trace m.ele: a .ele name is for a mesh, and this writes an operation stream"},
        {"gen --points 10 --out g.VTU", "--out g.VTU: a .vtu name is for a mesh"},
        {"run m.node --out m.node", "--out m.node would overwrite the input m.node"},
        {"gen --points 1e17 --out x.ops", "--points '1e17': too large (at most 4286578688)"},
        {"gen --points 1e12 --out x.ops", "--points '1e12': too large (at most 4286578688)"},
        {"refine --domain sphere --size 0.5 --budget 1e17",
         "--budget '1e17': with a decimal point or an exponent at most 2^53 (9007199254740992); write larger counts in digits"},
        {"run a.ops --threads 4097", "--threads '4097': too large (at most 4096)"},
        {"run a.ops --threads 99999999999999999999999", "--threads '99999999999999999999999': too large (at most 4096)"},
        {"refine --domain sphere --size 0.5 --threads 1e30", "--threads '1e30': too large (at most 4096)"},
    };
    for (const auto& [args, why] : cases) {
      INFO(args);
      const Result r = run_pdt(d, args);
      CHECK(r.code == 2);
      CHECK(r.err.rfind(std::string("pdt: ") + why, 0) == 0);
      CHECK(r.err.find("usage: pdt") != std::string::npos);
    }
  }
  SECTION("gen refuses a stream larger than the machine's memory before making it") {
    // The most points gen takes: 64 bytes each in memory, some 274 GB.
    const double memory = static_cast<double>(::sysconf(_SC_PHYS_PAGES)) * static_cast<double>(::sysconf(_SC_PAGE_SIZE));
    if (memory < 2.5e11) {
      const Result r = run_pdt(d, "gen --points 4286578688 --out '" + d.file("huge.ops") + "'");
      CHECK(r.code == 2);
      CHECK(r.err.find("--points 4,286,578,688: gen makes the whole stream in memory before writing it") !=
            std::string::npos);
      CHECK(r.err.find("give fewer points") != std::string::npos);
      CHECK_FALSE(std::filesystem::exists(d.file("huge.ops")));
    }
  }
  SECTION("an output directory that is not there is refused before the run") {
    const std::string ops = d.file("s.ops"), nowhere = d.file("missing/dir/m.vtu");
    pdt::OpStream s;
    s.ops.push_back({pdt::Operation::Kind::insert, {0, 0, 0}, 0});
    pdt::write_ops(ops, s);
    for (const std::string& args : {"run '" + ops + "' --out '" + nowhere + "'",
                                    "refine --domain sphere --size 0.5 --out '" + nowhere + "'"}) {
      INFO(args);
      const Result r = run_pdt(d, args);
      CHECK(r.code == 2);
      CHECK(r.err.find("--out " + nowhere + ": cannot write in") != std::string::npos);
      CHECK(r.out.empty());  // nothing ran
    }
    // Under /dev and /proc too, where existing names are written in place.
    for (const std::string& args : {"run '" + ops + "' --out /dev/pdt-no-such-dir/m.vtu",
                                    "run '" + ops + "' --out /proc/pdt-no-such-dir/m.node",
                                    std::string("gen --points 10 --out /dev/pdt-no-such-dir/x.ops")}) {
      INFO(args);
      const Result r = run_pdt(d, args);
      CHECK(r.code == 2);
      CHECK(r.err.find(": cannot write in '/") != std::string::npos);
      CHECK(r.out.empty());  // nothing ran
    }
    const Result r = run_pdt(d, "refine --domain sphere --size 0.5 --trace ''");
    CHECK(r.code == 2);
    CHECK(r.err.find("--trace needs a file name") != std::string::npos);
    // An output that is a directory (of TetGen's two files, either) is
    // refused before the run too, not after it.
    std::filesystem::create_directory(d.file("dir.vtu"));
    std::filesystem::create_directory(d.file("t.ele"));
    for (const auto& [args, dir] :
         {std::pair{"run '" + ops + "' --out '" + d.file("dir.vtu") + "'", d.file("dir.vtu")},
          std::pair{"refine --domain sphere --size 0.5 --out '" + d.file("dir.vtu") + "'", d.file("dir.vtu")},
          std::pair{"refine --domain sphere --size 0.5 --out '" + d.file("t.node") + "'", d.file("t.ele")}}) {
      INFO(args);
      const Result rd = run_pdt(d, args);
      CHECK(rd.code == 2);
      CHECK(rd.err.find("--out: cannot write '" + dir + "': it is a directory") != std::string::npos);
      CHECK(rd.out.empty());  // nothing ran
      CHECK_FALSE(std::filesystem::exists(d.file("t.node")));
    }
  }
  SECTION("a stream goes to /dev/stdout in place (no temporary in /dev, which only root may write)") {
#ifdef PDT_TOOL_PATH
    const std::string tool = std::string("'") + PDT_TOOL_PATH + "' ";
    // Through a pipe: the stream alone goes down it, the summary to stderr.
    const std::string piped = tool + "gen --points 3 --out /dev/stdout 2>'" + d.file("piped_err.txt") +
                              "' | grep -c '^i ' >'" + d.file("count.txt") + "'";
    CHECK(std::system(piped.c_str()) == 0);
    CHECK(pdt_test::read_file(d.file("count.txt")) == "3\n");
    CHECK(pdt_test::read_file(d.file("piped_err.txt")).find("wrote /dev/stdout: 3 insertions") == 0);
    // Into a file (> then >>): the stream is written where the shell's
    // descriptor stands, so the file is the stream, then two streams, and the
    // summary is not written over it. Both replay.
    const std::string file = d.file("to_file.ops");
    const std::string once = tool + "gen --points 3 --out /dev/stdout >'" + file + "' 2>/dev/null";
    const std::string again = tool + "gen --points 4 --seed 2 --out /dev/fd/1 >>'" + file + "' 2>/dev/null";
    CHECK(std::system(once.c_str()) == 0);
    const pdt::OpStream first = pdt::read_ops(file);
    CHECK(first.insert_count() == 3);
    CHECK(pdt_test::read_file(file).find("wrote") == std::string::npos);
    CHECK(std::system(again.c_str()) == 0);
    const std::string both = pdt_test::read_file(file);
    CHECK(both.find("# pdt operation stream: 3 insertions") == 0);
    CHECK(both.find("# pdt operation stream: 4 insertions") != std::string::npos);
    // A summary line on stdout and a stream elsewhere: the summary stays on stdout.
    const Result r = run_pdt(d, "gen --points 3 --out '" + d.file("elsewhere.ops") + "'");
    CHECK(r.code == 0);
    CHECK(r.out.find("wrote ") == 0);
    CHECK(r.err.empty());
    // refine's trace to standard output: the file is the trace, and replays.
    const std::string traced = d.file("traced.ops");
    const std::string refine = tool + "refine --domain sphere --size 0.3 --trace /dev/stdout >'" + traced + "' 2>'" +
                               d.file("refine_err.txt") + "'";
    CHECK(std::system(refine.c_str()) == 0);
    CHECK(pdt_test::read_file(d.file("refine_err.txt")).find("vertices") != std::string::npos);
    CHECK(pdt::read_ops(traced).insert_count() > 0);
    // /dev/fd/01 is no name the kernel knows (no leading zeros): not taken
    // for standard output, refused as a missing directory's file would be.
    const Result zero = run_pdt(d, "gen --points 3 --out /dev/fd/01");
    CHECK(zero.code == 2);
    // A descriptor open for reading only: refused before anything is written.
    const std::string ro = d.file("read_only.txt");
    pdt_test::write_file(ro, "keep\n");
    const std::string read_only = tool + "gen --points 3 --out /dev/fd/3 3<'" + ro + "' 2>'" + d.file("ro_err.txt") + "'";
    const int status = std::system(read_only.c_str());
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 2);
    CHECK(pdt_test::read_file(d.file("ro_err.txt")).find("not open for writing") != std::string::npos);
    CHECK(pdt_test::read_file(ro) == "keep\n");
#endif
  }
  SECTION("outputs through links, over protected files, beside a .smesh's nodes") {
#ifdef PDT_TOOL_PATH
    const std::string ops = d.file("small.ops");
    REQUIRE(run_pdt(d, "gen --points 200 --out '" + ops + "'").code == 0);
    // A link to a file in a missing folder: refused before the run.
    std::filesystem::create_symlink(d.file("missing/m.node"), d.file("dangling.node"));
    Result r = run_pdt(d, "run '" + ops + "' --out '" + d.file("dangling.node") + "'");
    CHECK(r.code == 2);
    CHECK(r.out.empty());
    CHECK(r.err.find("cannot write in") != std::string::npos);
    // A loop of links: refused before the run (nothing printed but why).
    std::filesystem::create_symlink("loop.vtu", d.file("loop.vtu"));
    std::filesystem::create_symlink("loop2.ops", d.file("loop1.ops"));
    std::filesystem::create_symlink("loop1.ops", d.file("loop2.ops"));
    for (const std::string& cmd : {"run '" + ops + "' --out '" + d.file("loop.vtu") + "'",
                                   "gen --points 10 --out '" + d.file("loop1.ops") + "'",
                                   "refine --domain sphere --size 0.5 --out '" + d.file("loop.vtu") + "'"}) {
      INFO(cmd);
      r = run_pdt(d, cmd);
      CHECK(r.code == 2);
      CHECK(r.out.empty());
      CHECK(r.err.find("Too many levels of symbolic links") != std::string::npos);
    }
    // A link to a file not there yet: made where the link points, whole.
    std::filesystem::create_symlink("target.vtu", d.file("link.vtu"));
    r = run_pdt(d, "run '" + ops + "' --out '" + d.file("link.vtu") + "'");
    CHECK(r.code == 0);
    CHECK(std::filesystem::is_symlink(d.file("link.vtu")));
    CHECK(std::filesystem::file_size(d.file("target.vtu")) > 0);
    // A private file stays private when replaced.
    pdt_test::write_file(d.file("private.vtu"), "old\n");
    std::filesystem::permissions(d.file("private.vtu"), std::filesystem::perms::owner_read |
                                                            std::filesystem::perms::owner_write);
    r = run_pdt(d, "run '" + ops + "' --out '" + d.file("private.vtu") + "'");
    CHECK(r.code == 0);
    CHECK(std::filesystem::status(d.file("private.vtu")).permissions() ==
          (std::filesystem::perms::owner_read | std::filesystem::perms::owner_write));
    // A .smesh without nodes reads the .node beside it: not an output.
    pdt_test::write_file(d.file("m.node"), "5 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 0.3 0.3 0.3\n");
    pdt_test::write_file(d.file("m.smesh"), "0 3 0 0\n0 0\n");
    r = run_pdt(d, "run '" + d.file("m.smesh") + "' --out '" + d.file("m.node") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("may take its points from") != std::string::npos);
    // --in-flight where nothing is submitted one at a time.
    r = run_pdt(d, "run '" + ops + "' --in-flight 5");
    CHECK(r.code == 2);
    CHECK(r.err.find("--in-flight applies to") != std::string::npos);
    CHECK(run_pdt(d, "run '" + ops + "' --in-flight 5 --threads 2").code == 0);
#endif
  }
  SECTION("a mesh output that names no file is refused before the run") {
    // TetGen's pair as hidden ".node" and ".ele" (a folder is refused by its
    // missing extension, and as a directory).
    for (const std::string& out : {d.file(".node"), d.file(".ELE")}) {
      INFO(out);
      const Result r = run_pdt(d, "refine --domain sphere --size 0.3 --out '" + out + "'");
      CHECK(r.code == 2);
      CHECK(r.out.empty());  // nothing ran
      CHECK(r.err.find("names no file") != std::string::npos);
    }
  }
  SECTION("an output and the input that are one file under two names") {
#ifdef PDT_TOOL_PATH
    // A hard link: same_file compares the files, not the names.
    const std::string input = d.file("in.xyz"), link = d.file("link.node");
    {
      std::ofstream f(input);
      f << "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n";
    }
    std::filesystem::create_hard_link(input, link);
    const Result r = run_pdt(d, "run '" + input + "' --out '" + link + "'");
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("would overwrite the input") != std::string::npos);
    CHECK(pdt_test::read_file(input) == "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n");
#endif
  }
  SECTION("an interrupted run leaves no partial output") {
#ifdef PDT_TOOL_PATH
    // Ctrl-C during a refinement that writes a trace: the trace's temporary
    // goes, and neither output exists (an older one would stay as it was).
    const std::string cmd = std::string("timeout -s INT 1 '") + PDT_TOOL_PATH +
                            "' refine --domain torus --size 0.006 --threads 2 --trace '" + d.file("k.ops") +
                            "' --out '" + d.file("k.vtu") + "' >/dev/null 2>&1";
    const int status = std::system(cmd.c_str());
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 124);  // timeout's status: it sent the signal
    for (const auto& e : std::filesystem::directory_iterator(d.path())) {
      INFO(e.path());
      CHECK(e.path().filename().string().find(".tmp.") == std::string::npos);
    }
    CHECK_FALSE(std::filesystem::exists(d.file("k.ops")));
    CHECK_FALSE(std::filesystem::exists(d.file("k.vtu")));
#endif
  }
  SECTION("a summary that cannot be written, a failed mesh write, a link to the trace leave nothing in place") {
#ifdef PDT_TOOL_PATH
    const std::string tool = std::string("'") + PDT_TOOL_PATH + "' ";
    auto status_of = [](const std::string& cmd) {
      const int status = std::system(cmd.c_str());
      return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    };
    const std::string err = d.file("err.txt");
    // Standard output closed: refused at once (the next file opened would
    // take its number, and the summary would go into an output).
    CHECK(status_of(tool + "gen --points 10 --out '" + d.file("g.ops") + "' >&- 2>'" + err + "'") == 2);
    CHECK(pdt_test::read_file(err).find("standard output is closed") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(d.file("g.ops")));
    // Standard input closed, read by name: refused, not read as what took its place.
    CHECK(status_of(tool + "run /dev/stdin <&- >/dev/null 2>'" + err + "'") == 2);
    CHECK(pdt_test::read_file(err).find("cannot read '/dev/stdin'") != std::string::npos);
    // A summary lost to a full device: the run fails before its outputs
    // are put in place.
    CHECK(status_of(tool + "refine --domain sphere --size 0.3 --out '" + d.file("f.vtu") + "' --trace '" +
                    d.file("f.ops") + "' >/dev/full 2>'" + err + "'") == 2);
    CHECK(pdt_test::read_file(err).find("cannot write the summary") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(d.file("f.vtu")));
    CHECK_FALSE(std::filesystem::exists(d.file("f.ops")));
    // A reader that stops after the first byte (head -c 1). When it closes
    // the pipe races with pdt's writes (stdout to a pipe is written at two
    // flushes: before the outputs go in place, and at exit), so three ends are
    // right: closed before the first flush, the run fails with nothing
    // written; between the two, it fails saying the outputs were written;
    // after both, the run succeeded.
    const int pipe_status = status_of("bash -c \"set -o pipefail; " + tool + "refine --domain sphere --size 0.2 --out '" +
                                      d.file("p.vtu") + "' 2>'" + err + "' | head -c 1 >/dev/null\"");
    const std::string pipe_err = pdt_test::read_file(err);
    INFO(pipe_status << ": " << pipe_err);
    const bool placed = std::filesystem::exists(d.file("p.vtu"));
    if (pipe_status == 0)
      CHECK((placed && pipe_err.empty()));
    else if (placed)
      CHECK((pipe_status == 2 &&
             pipe_err.find("the outputs were written before it (" + d.file("p.vtu") + ")") != std::string::npos));
    else
      CHECK((pipe_status == 2 && pipe_err.find("the output files were not written") != std::string::npos));
    // gen writes its one summary line after its file: a lost line says so.
    CHECK(status_of(tool + "gen --points 10 --out '" + d.file("w.ops") + "' >/dev/full 2>'" + err + "'") == 2);
    CHECK(pdt_test::read_file(err).find("the outputs were written before it") != std::string::npos);
    // The mesh's .ele passes a file-size limit the trace and .node stay
    // under: the run fails, and the older trace is as it was.
    pdt_test::write_file(d.file("s.ops"), "old\n");
    CHECK(status_of("bash -c \"ulimit -f 150; " + tool + "refine --domain sphere --size 0.15 --threads 2 --out '" +
                    d.file("s.node") + "' --trace '" + d.file("s.ops") + "' >/dev/null 2>'" + err + "'\"") == 2);
    CHECK(pdt_test::read_file(err).find("File too large") != std::string::npos);
    CHECK(pdt_test::read_file(d.file("s.ops")) == "old\n");
    // --out, a link to a file not there yet that is the trace's name: one
    // file written twice, refused before the run.
    std::filesystem::create_symlink("t.ops", d.file("m.vtu"));
    Result r = run_pdt(d, "refine --domain sphere --size 0.3 --out '" + d.file("m.vtu") + "' --trace '" +
                              d.file("t.ops") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("give the trace a name of its own") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(d.file("t.ops")));
    // The same through a chain of two links.
    std::filesystem::create_symlink("l2", d.file("c.vtu"));
    std::filesystem::create_symlink("t.ops", d.file("l2"));
    r = run_pdt(d, "refine --domain sphere --size 0.3 --out '" + d.file("c.vtu") + "' --trace '" + d.file("t.ops") + "'");
    CHECK(r.code == 2);
    CHECK(r.err.find("give the trace a name of its own") != std::string::npos);
    // One file under two names, neither there yet, one of them bare (run in
    // d), the trace's through a link: refused before the run, nothing written.
    std::filesystem::create_symlink("b.vtu", d.file("lb.ops"));
    std::filesystem::create_symlink("b.ele", d.file("le.ops"));
    for (const char* names : {"--out b.vtu --trace ./lb.ops", "--out ./b.vtu --trace lb.ops",
                              "--out b.node --trace ./le.ops"}) {
      INFO(names);
      CHECK(status_of("cd '" + d.path().string() + "' && " + tool + "refine --domain sphere --size 0.3 " + names +
                      " >/dev/null 2>'" + err + "'") == 2);
      CHECK(pdt_test::read_file(err).find("give the trace a name of its own") != std::string::npos);
      CHECK_FALSE(std::filesystem::exists(d.file("b.vtu")));
      CHECK_FALSE(std::filesystem::exists(d.file("b.ele")));
    }
    // Standard error closed, read by name: refused too (its place is held by
    // a descriptor that can be neither read nor written).
    CHECK(status_of(tool + "run /dev/stderr 2>&- >/dev/null") == 2);
#endif
  }
  SECTION("a stream without a box, piped to the engine") {
    // The engine needs the domain first; without a box line the stream is
    // read twice, which a pipe cannot be: refused, saying what to do. With
    // a box line, or sequentially, the pipe is fine.
    pdt::OpStream s;
    for (int i = 0; i < 50; ++i) s.ops.push_back({pdt::Operation::Kind::insert, {0.02 * i, 0.5, 0.03 * (i % 7)}, 0});
    const std::string no_box = d.file("no_box.ops"), with_box = d.file("with_box.ops");
    pdt::write_ops(no_box, s);
    s.box = pdt::Box{{0, 0, 0}, {1, 1, 1}};
    pdt::write_ops(with_box, s);
    const Result r = run_pdt(d, "run /dev/stdin --threads 2", no_box);
    CHECK(r.code == 2);
    CHECK(r.err.find("'box x0 y0 z0 x1 y1 z1' line") != std::string::npos);
    for (const std::string& ok : {std::string("run /dev/stdin"), std::string("run /dev/stdin --threads 2")}) {
      const Result fine = run_pdt(d, ok, ok.find("threads") != std::string::npos ? with_box : no_box);
      INFO(ok << "\n" << fine.err);
      CHECK(fine.code == 0);
      CHECK(fine.out.find("50 (0 duplicates)") != std::string::npos);
    }
  }
  SECTION("help") {
    for (const char* args : {"--help", "-h", "help", "help run", "gen --help", "run --help", "check --help"}) {
      INFO(args);
      const Result r = run_pdt(d, args);
      CHECK(r.code == 0);
      CHECK(r.out.find("usage: pdt") == 0);
      CHECK(r.err.empty());
    }
  }
}

TEST_CASE("pdt gen, run and check work end to end", "[cli]") {
  if (!have_tool()) return;
  TempDir d;
  const std::string ops = d.file("u.ops"), opsb = d.file("u.opsb"), mesh = d.file("mesh.node");
  Result r = run_pdt(d, "gen --dist uniform --points 3000 --remove-fraction 0.5 --interleaved --seed 9 --out '" + ops + "'");
  REQUIRE(r.code == 0);
  CHECK(r.out.find("3,000 insertions, 1,500 removals") != std::string::npos);
  r = run_pdt(d, "gen --dist=uniform --points=3e3 --remove-fraction=0.5 --interleaved --seed=9 --out='" + opsb + "'");
  REQUIRE(r.code == 0);
  // Same stream in both forms.
  CHECK(pdt::read_ops(ops).ops.size() == pdt::read_ops(opsb).ops.size());

  r = run_pdt(d, "run '" + opsb + "' --validate --out '" + mesh + "'");
  std::filesystem::copy_file(d.file("mesh.node"), d.file("m.node"));  // the .node before any change below
  INFO("stdout:\n" << r.out << "\nstderr:\n" << r.err);
  REQUIRE(r.code == 0);
  CHECK(r.out.find("vertices         1,500\n") != std::string::npos);
  CHECK(r.out.find("insertions       3,000 (0 duplicates)") != std::string::npos);
  CHECK(r.out.find("removals         1,500") != std::string::npos);
  CHECK(r.out.find("validate         ok") != std::string::npos);
  CHECK(r.out.find("peak memory") != std::string::npos);
  CHECK(r.out.find("wrote            " + d.file("mesh.node") + " and " + d.file("mesh.ele") + " (1,500 points") !=
        std::string::npos);
  CHECK(r.err.empty());  // no progress bar when stderr is not a terminal

  r = run_pdt(d, "check '" + mesh + "'");
  CHECK(r.code == 0);
  CHECK(r.out.find("valid Delaunay tetrahedralization: 1500 points") != std::string::npos);

  // Corrupt the mesh: drop the last tetrahedron (and fix the count).
  std::string ele = pdt_test::read_file(d.file("mesh.ele"));
  const std::size_t count = std::stoul(ele.substr(0, ele.find(' ')));
  ele.erase(ele.rfind('\n', ele.size() - 2) + 1);
  ele.replace(0, ele.find(' '), std::to_string(count - 1));
  write_file(d.file("mesh.ele"), ele);
  r = run_pdt(d, "check '" + mesh + "'");
  CHECK(r.code == 1);
  CHECK(r.out.find("INVALID") != std::string::npos);

  // --threads N: the parallel engine with N workers, same result, statistics shown.
  r = run_pdt(d, "run '" + ops + "' --threads 4 --validate --out '" + d.file("m.vtu") + "'");
  INFO("stdout:\n" << r.out << "\nstderr:\n" << r.err);
  CHECK(r.code == 0);
  CHECK(r.out.find("4 workers (parallel engine") != std::string::npos);
  CHECK(r.out.find("vertices         1,500\n") != std::string::npos);
  CHECK(r.out.find("workers          4,500 completed") != std::string::npos);
  CHECK(r.out.find("validate         ok") != std::string::npos);
  CHECK(std::filesystem::exists(d.file("m.vtu")));

  // --shrink: the storage given back after the replay, the same mesh (its
  // .node lists the vertices by id, which do not move), still valid.
  for (const char* threads : {"", " --threads 2"}) {
    r = run_pdt(d, "run '" + opsb + "' --shrink --validate --out '" + d.file("shrunk.node") + "'" + threads);
    INFO("stdout:\n" << r.out << "\nstderr:\n" << r.err);
    CHECK(r.code == 0);
    CHECK(r.out.find("shrink           the mesh ") != std::string::npos);
    CHECK(r.out.find("validate         ok") != std::string::npos);
    CHECK(r.out.find("vertices         1,500\n") != std::string::npos);
    if (*threads == '\0')  // the engine numbers the vertices in its own order
      CHECK(pdt_test::read_file(d.file("shrunk.node")) == pdt_test::read_file(d.file("m.node")));
    CHECK(run_pdt(d, "check '" + d.file("shrunk.node") + "'").code == 0);
  }

  // Duplicates are counted, not fatal; removals lower the multiplicity.
  write_file(d.file("dup.ops"), "i 0 0 0\ni 1 0 0\ni 0 1 0\ni 0 0 1\ni 0 0 0\nr 0\n");
  r = run_pdt(d, "run '" + d.file("dup.ops") + "' --validate");
  CHECK(r.code == 0);
  CHECK(r.out.find("(1 duplicates)") != std::string::npos);
  CHECK(r.out.find("vertices         4\n") != std::string::npos);
}

TEST_CASE("pdt gen is deterministic", "[cli]") {
  if (!have_tool()) return;
  TempDir d;
  for (const char* dist : {"normal", "sphere"}) {
    INFO(dist);
    const std::string a = d.file("a.opsb"), b = d.file("b.opsb");
    REQUIRE(run_pdt(d, std::string("gen --dist ") + dist + " --points 2000 --seed 3 --out '" + a + "'").code == 0);
    REQUIRE(run_pdt(d, std::string("gen --dist ") + dist + " --points 2000 --seed 3 --out '" + b + "'").code == 0);
    CHECK(pdt_test::read_file(a) == pdt_test::read_file(b));
    REQUIRE(run_pdt(d, std::string("gen --dist ") + dist + " --points 2000 --seed 4 --out '" + b + "'").code == 0);
    CHECK(pdt_test::read_file(a) != pdt_test::read_file(b));
  }
}

TEST_CASE("pdt run triangulates a point file as a batch, or in file order, with bounded streaming", "[cli]") {
  if (!have_tool()) return;
  TempDir d;
  std::string xyz;
  for (long long i = 0; i < 2000; ++i)
    xyz += std::to_string((i * 7919 % 1000) / 1000.0) + " " + std::to_string((i * 104729 % 997) / 997.0) + " " +
           std::to_string((i * 1299709 % 991) / 991.0) + "\n";
  write_file(d.file("cloud.xyz"), xyz);
  for (const char* mode : {"", " --in-order", " --threads 3", " --threads 3 --in-order"}) {
    INFO(mode);
    const Result r = run_pdt(d, "run '" + d.file("cloud.xyz") + "'" + mode + " --validate");
    INFO(r.out << r.err);
    REQUIRE(r.code == 0);
    CHECK(r.out.find(std::string(mode).find("in-order") != std::string::npos ? "(points in file order)"
                                                                             : "(points as a batch, spatial order)") !=
          std::string::npos);
    CHECK(r.out.find("insertions       2,000") != std::string::npos);
    CHECK(r.out.find("bytes/vertex") != std::string::npos);
    CHECK(r.out.find("validate         ok") != std::string::npos);
  }
  // A stream on the engine with a tiny window of operations in flight: same result.
  Result r = run_pdt(d, "gen --points 5000 --remove-fraction 0.8 --interleaved --out '" + d.file("s.opsb") + "'");
  REQUIRE(r.code == 0);
  r = run_pdt(d, "run '" + d.file("s.opsb") + "' --threads 4 --in-flight 8 --validate");
  INFO(r.out << r.err);
  REQUIRE(r.code == 0);
  CHECK(r.out.find("vertices         1,000\n") != std::string::npos);
  CHECK(r.out.find("in flight        at most 8 operations") != std::string::npos);
  CHECK(r.out.find("imbalance") != std::string::npos);
  CHECK(r.out.find("validate         ok") != std::string::npos);
}

TEST_CASE("PDT_HUGE_PAGES: 1 gives the same mesh as 0, anything else is refused naming it", "[cli]") {
  if (!have_tool()) return;
  TempDir d;
  // 60k points: the cell array (13 MB) passes the 4 MiB from which huge pages are advised.
  Result r = run_pdt(d, "gen --points 60000 --out '" + d.file("s.opsb") + "'");
  REQUIRE(r.code == 0);
  auto tets_line = [](const std::string& out) {
    const std::size_t at = out.find("finite tets");
    return at == std::string::npos ? std::string() : out.substr(at, out.find('\n', at) - at);
  };
  std::string expected;
  for (const char* value : {"0", "1", "", "2", "yes"}) {
    INFO("PDT_HUGE_PAGES='" << value << "'");
    ::setenv("PDT_HUGE_PAGES", value, 1);
    r = run_pdt(d, "run '" + d.file("s.opsb") + "' --validate");
    ::unsetenv("PDT_HUGE_PAGES");
    INFO(r.out << r.err);
    if (std::string(value) == "2" || std::string(value) == "yes") {
      CHECK(r.code == 2);
      CHECK(r.err.find(std::string("PDT_HUGE_PAGES='") + value + "' is not a valid value (expected 0 or 1)") !=
            std::string::npos);
      CHECK(r.out.empty());
      continue;
    }
    REQUIRE(r.code == 0);
    CHECK(r.out.find("validate         ok") != std::string::npos);
    const std::string tets = tets_line(r.out);
    CHECK_FALSE(tets.empty());
    if (expected.empty()) expected = tets;
    CHECK(tets == expected);
  }
}
