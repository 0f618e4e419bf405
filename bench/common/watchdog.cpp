// SPDX-License-Identifier: MIT
#include "common/watchdog.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>

namespace pdt_bench {

Watchdog::Watchdog() : thread_([this] { loop(); }) {}

Watchdog::~Watchdog() {
  {
    std::lock_guard<std::mutex> lock(m_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

void Watchdog::arm(const std::string& what, double seconds) {
  {
    std::lock_guard<std::mutex> lock(m_);
    what_ = what;
    seconds_ = seconds;
    armed_ = seconds > 0;
    const double capped = std::min(seconds, 1e9);  // "inf" or huge: no overflow of the time point
    deadline_ = std::chrono::steady_clock::now() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(capped));
  }
  cv_.notify_all();
}

void Watchdog::disarm() {
  std::lock_guard<std::mutex> lock(m_);
  armed_ = false;
}

void Watchdog::loop() {
  std::unique_lock<std::mutex> lock(m_);
  while (!stop_) {
    if (!armed_) {
      cv_.wait(lock);
      continue;
    }
    if (cv_.wait_until(lock, deadline_) == std::cv_status::timeout && armed_ && !stop_ &&
        std::chrono::steady_clock::now() >= deadline_) {
      std::fflush(stdout);
      std::printf("\nHANG: %s did not finish within %g s; aborting (exit 3)\n", what_.c_str(), seconds_);
      std::fprintf(stderr, "HANG: %s did not finish within %g s; aborting (exit 3)\n", what_.c_str(), seconds_);
      std::fflush(stdout);
      std::fflush(stderr);
      std::_Exit(3);
    }
  }
}

}  // namespace pdt_bench
