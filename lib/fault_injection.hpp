// SPDX-License-Identifier: MIT
#pragma once
// Allocation-failure injection, for the tests of exception safety only. In a
// build with PDT_FAULT_INJECTION (the pdt_fault library the fault tests link),
// PDT_FAULT_POINT(site) marks a place where memory is obtained; once armed
// with a countdown k, the k-th point reached (from 0) throws std::bad_alloc,
// as a failed allocation there would. In every other build it is nothing.
#include <cstdint>

#ifdef PDT_FAULT_INJECTION
namespace pdt::detail::fault {
void point(const char* site);            // throws std::bad_alloc when the countdown runs out
void arm(std::uint64_t countdown);       // the countdown-th point from now fails (once)
void disarm();
std::uint64_t points_seen();             // points reached since the last arm()
const char* last_failed_site();          // where the last injected failure was
}  // namespace pdt::detail::fault
#define PDT_FAULT_POINT(site) ::pdt::detail::fault::point(site)
#else
#define PDT_FAULT_POINT(site) ((void)0)
#endif
