// SPDX-License-Identifier: MIT
#include "common/child.hpp"

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <vector>

#include "pdt/error.hpp"

namespace pdt_bench {

namespace {

struct Header {
  char ok = 0;
  char error[256] = {};
};

bool write_all(int fd, const char* p, std::size_t n) {
  while (n > 0) {
    const ssize_t w = write(fd, p, n);
    if (w <= 0) return false;
    p += w;
    n -= static_cast<std::size_t>(w);
  }
  return true;
}

std::size_t read_all(int fd, char* p, std::size_t n) {
  std::size_t got = 0;
  while (got < n) {
    const ssize_t r = read(fd, p + got, n - got);
    if (r <= 0) break;
    got += static_cast<std::size_t>(r);
  }
  return got;
}

}  // namespace

ChildStatus run_in_child(const std::function<void(void* out)>& body, void* out, std::size_t size) {
  int fd[2];
  if (pipe(fd) != 0) throw pdt::Error(pdt::ErrorCode::io_failure, "pipe failed");
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid < 0) throw pdt::Error(pdt::ErrorCode::io_failure, "fork failed");
  if (pid == 0) {
    close(fd[0]);
    Header h;
    std::vector<char> result(size);
    try {
      body(result.data());
      h.ok = 1;
    } catch (const std::exception& e) {
      std::snprintf(h.error, sizeof h.error, "%s", e.what());
    }
    std::fflush(stdout);
    std::fflush(stderr);
    const bool w = write_all(fd[1], reinterpret_cast<const char*>(&h), sizeof h) &&
                   write_all(fd[1], result.data(), result.size());
    _exit(w ? 0 : 1);
  }
  close(fd[1]);
  Header h;
  std::vector<char> result(size);
  const bool got = read_all(fd[0], reinterpret_cast<char*>(&h), sizeof h) == sizeof h &&
                   read_all(fd[0], result.data(), size) == size;
  close(fd[0]);
  int status = 0;
  rusage ru{};
  wait4(pid, &status, 0, &ru);
  ChildStatus st;
  st.peak_kib = ru.ru_maxrss;
  if (WIFEXITED(status)) st.exit_code = WEXITSTATUS(status);
  if (!got || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    char why[128];
    if (WIFSIGNALED(status))
      std::snprintf(why, sizeof why, "the configuration's process died (signal %d)", WTERMSIG(status));
    else
      std::snprintf(why, sizeof why, "the configuration's process died (exit status %d)",
                    WIFEXITED(status) ? WEXITSTATUS(status) : status);
    st.error = why;
    return st;
  }
  if (!h.ok) {
    h.error[sizeof h.error - 1] = 0;
    st.error = h.error;
    return st;
  }
  std::memcpy(out, result.data(), size);
  st.ok = true;
  return st;
}

}  // namespace pdt_bench
