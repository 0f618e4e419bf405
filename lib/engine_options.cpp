// SPDX-License-Identifier: MIT
// EngineOptions from the environment, the allocator's name, summed statistics.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <type_traits>

#include "io_util.hpp"
#include "pdt/engine.hpp"
#include "pdt/error.hpp"

namespace pdt {

namespace {

// A plain decimal number: digits, at most one '.', then an optional
// exponent (floating fields only): no sign, space, hex or "inf".
bool plain_decimal(const char* s, bool fraction_allowed) {
  const char* p = s;
  bool digits = false;
  while (*p >= '0' && *p <= '9') ++p, digits = true;
  if (!fraction_allowed) return digits && *p == '\0';
  if (*p == '.') {
    ++p;
    while (*p >= '0' && *p <= '9') ++p, digits = true;
  }
  if (!digits) return false;
  if (*p == 'e' || *p == 'E') {
    ++p;
    if (*p == '+' || *p == '-') ++p;
    if (!(*p >= '0' && *p <= '9')) return false;
    while (*p >= '0' && *p <= '9') ++p;
  }
  return *p == '\0';
}

// Reads variable `name` into field if it is set: a whole number (integral
// fields) or a decimal number (floating ones) in [0, most]; anything else is
// refused naming the variable and the range.
template <class T>
bool env_number(const char* name, T& field, double most) {
  const char* s = std::getenv(name);
  if (!s || !*s) return false;
  constexpr bool whole = std::is_integral_v<T>;
  if constexpr (whole) most = std::min(most, static_cast<double>(std::numeric_limits<T>::max()));
  double v = -1;  // parse_double: from_chars, whatever the locale's decimal point
  if (plain_decimal(s, !whole) && detail::parse_double(s, v) != detail::NumStatus::ok) v = -1;
  if (!(v >= 0 && v <= most)) {
    char range[96];
    std::snprintf(range, sizeof range, whole ? "a whole number from 0 to %.0f" : "a number from 0 to %g", most);
    throw Error(ErrorCode::invalid_argument,
                std::string(name) + "='" + s + "' is not a valid value (expected " + range + ")");
  }
  field = static_cast<T>(v);
  return true;
}

}  // namespace

EngineOptions EngineOptions::from_environment(EngineOptions o) {
  constexpr double any = 1e12;  // no bound of its own: the field's type bounds it
  if (!env_number("PDT_WORKERS", o.workers, EngineOptions::max_workers))
    env_number("PDT_THREADS", o.workers, EngineOptions::max_workers);  // PDT_THREADS: the older name
  env_number("PDT_BLOCKS_PER_AXIS", o.blocks_per_axis, EngineOptions::max_blocks_per_axis);
  const bool low_set = env_number("PDT_CONTENTION_LOW", o.contention_low, 1);
  const bool high_set = env_number("PDT_CONTENTION_HIGH", o.contention_high, 1);
  if ((low_set || high_set) && o.contention_low > o.contention_high) {
    auto value = [](const char* name, double v, bool set) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "%s=%g%s", name, v, set ? "" : " (not set: the default)");
      return std::string(buf);
    };
    throw Error(ErrorCode::invalid_argument,
                value("PDT_CONTENTION_LOW", o.contention_low, low_set) + " is above " +
                    value("PDT_CONTENTION_HIGH", o.contention_high, high_set) +
                    "; expected PDT_CONTENTION_LOW <= PDT_CONTENTION_HIGH (u- <= u+)");
  }
  env_number("PDT_CONTENTION_WINDOW", o.contention_window, any);
  env_number("PDT_GRID_SLOTS", o.grid_slots, any);
  env_number("PDT_ESCALATE_AFTER", o.escalate_after, any);
  unsigned stealing = o.stealing ? 1 : 0;
  if (env_number("PDT_STEALING", stealing, 1)) o.stealing = stealing == 1;
  unsigned rebalance = o.rebalance ? 1 : 0;
  if (env_number("PDT_REBALANCE", rebalance, 1)) o.rebalance = rebalance == 1;
  return o;
}

EngineOptions EngineOptions::from_environment() { return from_environment(EngineOptions{}); }

const char* allocator_name() {
#ifdef PDT_USE_MIMALLOC
  return "mimalloc";
#else
  return "pool";
#endif
}

double EngineStats::imbalance() const {
  if (workers.empty()) return 1;
  double sum = 0, most = 0;
  for (const WorkerStats& w : workers) {
    sum += static_cast<double>(w.completed);
    most = std::max(most, static_cast<double>(w.completed));
  }
  return sum > 0 ? most / (sum / static_cast<double>(workers.size())) : 1;
}

WorkerStats EngineStats::total() const {
  WorkerStats t;
  for (const WorkerStats& w : workers) {
    t.completed += w.completed;
    t.attempts += w.attempts;
    t.rollbacks += w.rollbacks;
    t.deferred += w.deferred;
    t.sleeps += w.sleeps;
    t.steals += w.steals;
    t.escalated += w.escalated;
    t.seconds_asleep += w.seconds_asleep;
    t.seconds_idle += w.seconds_idle;
    t.max_rollbacks_per_completed = std::max(t.max_rollbacks_per_completed, w.max_rollbacks_per_completed);
  }
  return t;
}

}  // namespace pdt
