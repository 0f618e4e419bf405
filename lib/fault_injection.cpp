// SPDX-License-Identifier: MIT
// See fault_injection.hpp. Compiled into every build, empty unless
// PDT_FAULT_INJECTION is defined.
#include "fault_injection.hpp"

#ifdef PDT_FAULT_INJECTION
#include <atomic>
#include <new>

namespace pdt::detail::fault {

namespace {
std::atomic<bool> armed{false};
std::atomic<std::uint64_t> remaining{0};
std::atomic<std::uint64_t> seen{0};
std::atomic<const char*> failed_site{""};
}  // namespace

void point(const char* site) {
  seen.fetch_add(1, std::memory_order_relaxed);
  if (!armed.load(std::memory_order_acquire)) return;
  if (remaining.fetch_sub(1, std::memory_order_acq_rel) != 0) return;
  armed.store(false, std::memory_order_release);
  failed_site.store(site, std::memory_order_relaxed);
  throw std::bad_alloc();
}

void arm(std::uint64_t countdown) {
  seen.store(0, std::memory_order_relaxed);
  remaining.store(countdown, std::memory_order_relaxed);
  armed.store(true, std::memory_order_release);
}

void disarm() { armed.store(false, std::memory_order_release); }
std::uint64_t points_seen() { return seen.load(std::memory_order_relaxed); }
const char* last_failed_site() { return failed_site.load(std::memory_order_relaxed); }

}  // namespace pdt::detail::fault
#endif
