// SPDX-License-Identifier: MIT
#pragma once
// Runs one benchmark configuration in a child process (fork), so that its
// peak memory is its own and a crash or a hang is its own too. The parent
// must not have started threads (TBB, OpenMP) before forking: start them in
// the child.
#include <cstddef>
#include <cstdio>
#include <exception>
#include <functional>
#include <string>
#include <type_traits>

namespace pdt_bench {

struct ChildStatus {
  bool ok = false;
  std::string error;  // why not ok: the exception the child threw, or how it died
  long peak_kib = 0;  // the child's peak resident memory (getrusage of the child)
  int exit_code = -1;  // the child's exit status if it exited (3: its watchdog saw a HANG), else -1
};

// Runs body in a child. body writes its result (size bytes) to *out in the
// child; the bytes come back to the parent's *out through a pipe.
ChildStatus run_in_child(const std::function<void(void* out)>& body, void* out, std::size_t size);

// fn() -> T, T trivially copyable (plain data), run in a child.
template <class T, class Fn>
ChildStatus in_child(Fn fn, T& out) {
  static_assert(std::is_trivially_copyable_v<T>, "a child's result crosses a pipe as bytes");
  return run_in_child([&](void* o) { *static_cast<T*>(o) = fn(); }, &out, sizeof(T));
}

}  // namespace pdt_bench
