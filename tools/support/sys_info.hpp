// SPDX-License-Identifier: MIT
#pragma once
// Tool support (not part of libpdt): process memory, timing and a terminal progress line for the tool
// and the benchmarks. Linux-specific where it must be (/proc); elsewhere the
// memory figures are 0.
#include <chrono>
#include <cstdint>
#include <string>

namespace pdt::support {

// Peak resident set size of this process (VmHWM), in bytes; 0 if unknown.
std::uint64_t peak_rss_bytes();
// Current resident set size (VmRSS), in bytes; 0 if unknown.
std::uint64_t current_rss_bytes();

// Wall-clock stopwatch (steady clock). Starts running on construction.
class Stopwatch {
 public:
  Stopwatch() : start_(clock::now()) {}
  void restart() {
    start_ = clock::now();
    accumulated_ = 0;
    running_ = true;
  }
  void stop() {
    if (running_) accumulated_ += since(start_);
    running_ = false;
  }
  void resume() {
    if (!running_) start_ = clock::now();
    running_ = true;
  }
  double seconds() const { return accumulated_ + (running_ ? since(start_) : 0.0); }

 private:
  using clock = std::chrono::steady_clock;
  static double since(clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); }
  clock::time_point start_;
  double accumulated_ = 0;
  bool running_ = true;
};

// A one-line progress display on stderr, shown only when stderr is a terminal
// (so logs and pipes never get control characters), redrawn at most ~10 times
// a second, and only for runs that last over half a second. update() is
// cheap enough for a per-operation loop: between redraws it is one compare.
// total 0: unknown (a text stream announces no count): the count and the
// time so far, no percentage.
class ProgressBar {
 public:
  ProgressBar(std::string label, std::uint64_t total);
  ~ProgressBar();  // clears the line
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  void update(std::uint64_t done) {
    if (done >= next_check_) slow_update(done);
  }
  void finish();  // clears the line; further updates are ignored
  bool enabled() const { return enabled_; }

 private:
  void slow_update(std::uint64_t done);
  std::string label_;
  std::uint64_t total_;
  std::uint64_t next_check_;
  std::uint64_t step_;
  bool enabled_;
  bool drawn_ = false;
  Stopwatch clock_;
  double last_draw_ = 0;
};

// "1.23 s", "456 ms"; "12.3 MB"; "1,234,567".
std::string format_seconds(double s);
std::string format_megabytes(std::uint64_t bytes);
std::string format_count(std::uint64_t n);

}  // namespace pdt::support
