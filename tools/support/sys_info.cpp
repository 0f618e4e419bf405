// SPDX-License-Identifier: MIT
// Tool support: see sys_info.hpp.
#include "sys_info.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstring>

namespace pdt::support {

namespace {

// A "Key:   123 kB" line of /proc/self/status, in bytes; 0 if absent.
std::uint64_t proc_status_kb(const char* key) {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (f == nullptr) return 0;
  char line[256];
  std::uint64_t kb = 0;
  const std::size_t klen = std::strlen(key);
  while (std::fgets(line, sizeof line, f) != nullptr) {
    if (std::strncmp(line, key, klen) == 0 && line[klen] == ':') {
      unsigned long long v = 0;
      if (std::sscanf(line + klen + 1, "%llu", &v) == 1) kb = v;
      break;
    }
  }
  std::fclose(f);
  return kb * 1024;
}

}  // namespace

std::uint64_t peak_rss_bytes() { return proc_status_kb("VmHWM"); }
std::uint64_t current_rss_bytes() { return proc_status_kb("VmRSS"); }

ProgressBar::ProgressBar(std::string label, std::uint64_t total)
    : label_(std::move(label)), total_(total), enabled_(::isatty(STDERR_FILENO) == 1) {
  // Look at the clock every `step_` updates (about 1/1000 of the work), and
  // never when disabled.
  step_ = total_ ? total_ / 1000 + 1 : 1024;  // total unknown (0): every 1024 updates
  next_check_ = enabled_ ? step_ : ~std::uint64_t{0};
}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::slow_update(std::uint64_t done) {
  next_check_ = done + step_;
  const double t = clock_.seconds();
  if (t < 0.5 || t - last_draw_ < 0.1) return;  // short runs: no display at all
  last_draw_ = t;
  char buf[256];
  const double frac = total_ ? static_cast<double>(done) / static_cast<double>(total_) : 0.0;
  if (total_ == 0) {  // a count without an end (a text stream announces none)
    std::snprintf(buf, sizeof buf, "\r%s: %s done, %s elapsed   ", label_.c_str(), format_count(done).c_str(),
                  format_seconds(t).c_str());
  } else if (frac > 0.001) {
    const double eta = t * (1 - frac) / frac;
    std::snprintf(buf, sizeof buf, "\r%s: %5.1f%% (%s / %s), %s elapsed, ~%s left   ", label_.c_str(), 100 * frac,
                  format_count(done).c_str(), format_count(total_).c_str(), format_seconds(t).c_str(),
                  format_seconds(eta).c_str());
  } else {
    std::snprintf(buf, sizeof buf, "\r%s: %s / %s   ", label_.c_str(), format_count(done).c_str(),
                  format_count(total_).c_str());
  }
  std::fputs(buf, stderr);
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (drawn_) {
    std::fputs("\r\033[K", stderr);  // carriage return + erase line
    std::fflush(stderr);
  }
  drawn_ = false;
  next_check_ = ~std::uint64_t{0};
}

std::string format_seconds(double s) {
  char buf[64];
  if (s < 1) std::snprintf(buf, sizeof buf, "%.0f ms", s * 1000);
  else if (s < 120) std::snprintf(buf, sizeof buf, "%.2f s", s);
  else std::snprintf(buf, sizeof buf, "%.0f min %02.0f s", static_cast<double>(static_cast<long>(s) / 60),
                     static_cast<double>(static_cast<long>(s) % 60));
  return buf;
}

std::string format_megabytes(std::uint64_t bytes) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f MB", static_cast<double>(bytes) / 1e6);
  return buf;
}

std::string format_count(std::uint64_t n) {
  std::string digits = std::to_string(n), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return out;
}

}  // namespace pdt::support
