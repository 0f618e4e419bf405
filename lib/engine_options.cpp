// SPDX-License-Identifier: MIT
// EngineOptions from the environment, the allocator's name, summed statistics.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <type_traits>

#include "pdt/engine.hpp"
#include "pdt/error.hpp"

namespace pdt {

namespace {

template <class T>
bool env_number(const char* name, T& field) {
  const char* s = std::getenv(name);
  if (!s || !*s) return false;
  char* end = nullptr;
  double v = std::strtod(s, &end);
  bool ok = end && *end == '\0' && std::isfinite(v) && v >= 0;
  std::string expected = "a non-negative number";
  if constexpr (std::is_integral_v<T>) {  // whole, and in T's range: no silent wrap
    const double most = std::min(1e12, static_cast<double>(std::numeric_limits<T>::max()));
    ok = ok && v == std::floor(v) && v <= most;
    expected = "a whole number from 0 to " + std::to_string(static_cast<unsigned long long>(most));
  }
  if (!ok)
    throw Error(ErrorCode::invalid_argument,
                std::string(name) + "='" + s + "' is not a valid value (expected " + expected + ")");
  field = static_cast<T>(v);
  return true;
}

}  // namespace

EngineOptions EngineOptions::from_environment(EngineOptions o) {
  if (!env_number("PDT_WORKERS", o.workers)) env_number("PDT_THREADS", o.workers);  // PDT_THREADS: the 0.1 name
  env_number("PDT_BLOCKS_PER_AXIS", o.blocks_per_axis);
  env_number("PDT_CONTENTION_LOW", o.contention_low);
  env_number("PDT_CONTENTION_HIGH", o.contention_high);
  env_number("PDT_CONTENTION_WINDOW", o.contention_window);
  env_number("PDT_GRID_SLOTS", o.grid_slots);
  env_number("PDT_ESCALATE_AFTER", o.escalate_after);
  unsigned stealing = o.stealing ? 1 : 0;
  if (env_number("PDT_STEALING", stealing)) {
    if (stealing > 1) throw Error(ErrorCode::invalid_argument, "PDT_STEALING must be 0 or 1");
    o.stealing = stealing == 1;
  }
  unsigned rebalance = o.rebalance ? 1 : 0;
  if (env_number("PDT_REBALANCE", rebalance)) {
    if (rebalance > 1) throw Error(ErrorCode::invalid_argument, "PDT_REBALANCE must be 0 or 1");
    o.rebalance = rebalance == 1;
  }
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
    t.max_rollbacks_per_completed = std::max(t.max_rollbacks_per_completed, w.max_rollbacks_per_completed);
  }
  return t;
}

}  // namespace pdt
