// SPDX-License-Identifier: MIT
// pdt: command-line tool to generate operation streams, replay them on a
// triangulation, refine a mesh of a domain, and check meshes. Run `pdt --help`.
// Each command lives in tools/cmd_<name>.cpp.
//
// Exit status: 0 success; 1 a check failed (`check` found an invalid mesh,
// `run --validate` found a broken triangulation, `refine` missed its bounds);
// 2 usage error or any failure (bad input, I/O). Every failure is one
// "pdt: ..." line on stderr; nothing escapes as an uncaught exception.
#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <vector>

#include "cli.hpp"
#include "pdt/error.hpp"

namespace pdt::detail {
void unlink_temporaries() noexcept;  // lib/io_util.hpp: libpdt's outputs not yet renamed into place
}

namespace {

using namespace pdt_cli;

// Interrupted (Ctrl-C, kill, a closed terminal): the files being written go
// (each is a temporary until it is complete), then the signal does what it
// would have done.
extern "C" void on_interrupt(int sig) {
  pdt::detail::unlink_temporaries();
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

const char* const main_usage =
    "usage: pdt <command> [options]\n"
    "\n"
    "commands:\n"
    "  gen     generate an operation stream (insertions, removals)\n"
    "  run     replay an operation stream, or triangulate a point file\n"
    "  refine  mesh a domain (sphere, torus, ...) with a parallel Delaunay refiner\n"
    "  check   check that a TetGen mesh is a Delaunay tetrahedralization\n"
    "\n"
    "Run 'pdt <command> --help' for a command's options.\n"
    "Exit status: 0 success, 1 check failed, 2 error.\n";


int dispatch(int argc, char** argv) {
  std::vector<std::string> a(argv + 1, argv + argc);
  if (a.empty()) usage_error(main_usage, "no command given");
  const std::string cmd = a[0];
  a.erase(a.begin());
  struct Command {
    const char* name;
    const char* usage;
    int (*run)(Args);
  };
  const Command commands[] = {{"gen", gen_usage, cmd_gen},
                              {"run", run_usage, cmd_run},
                              {"refine", refine_usage, cmd_refine},
                              {"check", check_usage, cmd_check}};
  if (is_help(cmd) || cmd == "help") {
    for (const Command& c : commands)
      if (!a.empty() && a[0] == c.name) {
        std::fputs(c.usage, stdout);
        return 0;
      }
    std::fputs(main_usage, stdout);
    return 0;
  }
  for (const Command& c : commands)
    if (cmd == c.name) return c.run(Args(std::move(a), c.usage));
  usage_error(main_usage, "unknown command '" + cmd + "'");
}

}  // namespace

int main(int argc, char** argv) {
  // A standard descriptor closed by the caller (pdt ... >&-) would be the
  // next file pdt opens, and the summary or an error message would be written
  // into an output (a trace, a mesh). Each closed one is held by a descriptor
  // that can be neither read nor written (O_PATH), so using it fails as a
  // closed one does (by name too: /dev/stdin is refused) and no file takes its
  // number; a closed standard output is refused at once.
  bool stdout_closed = false;
  for (int fd = 0; fd <= 2; ++fd)
    if (::fcntl(fd, F_GETFD) == -1 && errno == EBADF) {
      stdout_closed = stdout_closed || fd == 1;
      const int held = ::open("/dev/null", O_PATH | O_CLOEXEC);
      if (held >= 0 && held != fd) {  // the lowest free number: fd itself, unless /dev/null was refused
        ::dup2(held, fd);
        ::close(held);
      }
    }
  if (stdout_closed) {
    std::fputs("pdt: standard output is closed; pdt writes its summary there (send it to /dev/null to drop it); "
               "nothing was done\n",
               stderr);
    return 2;
  }
  // A closed pipe on stdout (pdt run ... | head) is then a write error that
  // ends the run with one "pdt: ..." line and status 2, not a silent SIGPIPE.
  std::signal(SIGPIPE, SIG_IGN);
  // Past a file-size limit (ulimit -f) a write then fails with EFBIG, which
  // discards the temporaries as any write error does, instead of SIGXFSZ
  // killing the process and leaving them.
  std::signal(SIGXFSZ, SIG_IGN);
  for (int sig : {SIGINT, SIGTERM, SIGHUP})
    if (std::signal(sig, on_interrupt) == SIG_IGN) std::signal(sig, SIG_IGN);  // ignored by the parent: stays so
  try {
    const int status = dispatch(argc, argv);
    // A summary lost to a full disk or a closed pipe is a failure too.
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
      const int err = errno != 0 ? errno : EIO;
      if (outputs_placed().empty())
        std::fprintf(stderr, "pdt: cannot write to standard output: %s\n", std::strerror(err));
      else  // the summary up to the outputs was written (require_summary_written), then the rest was lost
        std::fprintf(stderr,
                     "pdt: cannot write the end of the summary to standard output: %s; the outputs were written "
                     "before it (%s)\n",
                     std::strerror(err), outputs_placed().c_str());
      return 2;
    }
    return status;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "pdt: %s\n\n%s", e.message.c_str(), e.usage);
  } catch (const pdt::Error& e) {
    std::fprintf(stderr, "pdt: %s\n", e.what());
  } catch (const std::bad_alloc&) {
    // pdt reserves address space for its arrays up front (tens of GiB, not
    // backed until used): a limit on it fails that first, with plenty of
    // memory free.
    struct rlimit as;
    if (::getrlimit(RLIMIT_AS, &as) == 0 && as.rlim_cur != RLIM_INFINITY)
      std::fprintf(stderr,
                   "pdt: out of memory, or of address space: the address-space limit (ulimit -v) is %llu MiB, and "
                   "pdt reserves address space for its arrays up front (up to some 100 GiB, backed only as used); "
                   "raise or remove the limit (ulimit -v unlimited)\n",
                   static_cast<unsigned long long>(as.rlim_cur >> 20));
    else
      std::fprintf(stderr, "pdt: out of memory\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pdt: internal error: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "pdt: internal error (unknown exception)\n");
  }
  return 2;
}
