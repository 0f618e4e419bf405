// SPDX-License-Identifier: MIT
#pragma once
// A configuration that never finishes (an engine that livelocks or loops) must
// not eat a whole benchmark session: past its deadline the run prints HANG
// with what was running (the tables and CSV rows so far are already out) and
// exits 3.
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>

namespace pdt_bench {

class Watchdog {
 public:
  Watchdog();
  ~Watchdog();
  void arm(const std::string& what, double seconds);  // seconds <= 0: never
  void disarm();

 private:
  void loop();
  std::mutex m_;
  std::condition_variable cv_;
  std::string what_;
  double seconds_ = 0;
  bool armed_ = false, stop_ = false;
  std::chrono::steady_clock::time_point deadline_;
  std::thread thread_;
};

// Arms a watchdog (if any) for the lifetime of one configuration.
struct WatchdogGuard {
  WatchdogGuard(Watchdog* dog, const std::string& what, double seconds) : dog_(dog) {
    if (dog_) dog_->arm(what, seconds);
  }
  ~WatchdogGuard() {
    if (dog_) dog_->disarm();
  }
  WatchdogGuard(const WatchdogGuard&) = delete;
  WatchdogGuard& operator=(const WatchdogGuard&) = delete;

 private:
  Watchdog* dog_;
};

}  // namespace pdt_bench
