// SPDX-License-Identifier: MIT
#pragma once
// The contention manager of paper §3.3, per worker: it keeps the worker's
// progress ratio u = completed / attempted over a window of attempts and, at
// the end of each window, judges it: below u- (contention_low) the worker
// should sleep, above u+ (contention_high) it should wake a sleeper. The
// engine never lets the last running worker sleep, so some worker always
// makes progress. Memoryless: a woken worker starts a fresh window.
//
// Invariant: completed_ <= attempted_ < window_ between judgements.
#include <cassert>
#include <cstdint>

namespace pdt::detail {

class ContentionManager {
 public:
  enum class Verdict { carry_on, sleep, wake_another };

  ContentionManager(double low, double high, unsigned window) : low_(low), high_(high), window_(window ? window : 1) {}

  void attempted() { ++attempted_; }
  void completed() {
    ++completed_;
    assert(completed_ <= attempted_);
  }
  Verdict judge() {
    if (attempted_ < window_) return Verdict::carry_on;
    const double u = static_cast<double>(completed_) / attempted_;
    forget();
    if (u < low_) return Verdict::sleep;
    if (u > high_) return Verdict::wake_another;
    return Verdict::carry_on;
  }
  void forget() { attempted_ = completed_ = 0; }

 private:
  double low_, high_;
  std::uint32_t window_;
  std::uint32_t attempted_ = 0, completed_ = 0;
};

}  // namespace pdt::detail
