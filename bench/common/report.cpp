// SPDX-License-Identifier: MIT
#include "common/report.hpp"

#include <cstdio>

#include "pdt/error.hpp"

namespace pdt_bench {

void Table::print() const {
  const int lw = 38, cw = 10;
  const int gw = cw * int(threads_.size());
  std::printf("%-*s", lw, "");
  for (const auto& g : groups_)
    std::printf(" |%*s%-*s", (gw - int(g.size())) / 2, "", gw - (gw - int(g.size())) / 2, g.c_str());
  std::printf("\n%-*s", lw, "#Threads");
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    std::printf(" |");
    for (unsigned t : threads_) std::printf("%*u", cw, t);
  }
  std::printf("\n");
  for (const auto& row : rows_) {
    std::printf("%-*s", lw, row.first.c_str());
    for (std::size_t i = 0; i < row.second.size(); ++i) {
      if (i % threads_.size() == 0) std::printf(" |");
      std::printf("%*s", cw, row.second[i].c_str());
    }
    std::printf("\n");
  }
  std::fflush(stdout);
}

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string fmt_u(std::uint64_t v) { return std::to_string(v); }

std::string fmt_ratio(double num, double den) { return num > 0 && den > 0 ? fmt("%.2f", num / den) : "-"; }

CsvWriter::CsvWriter(const std::string& path, const std::string& header) {
  if (path.empty()) return;
  f_.open(path);
  if (!f_) throw pdt::Error(pdt::ErrorCode::io_failure, "cannot write " + path);
  on_ = true;
  f_ << header << "\n";
}

void CsvWriter::row(const std::vector<std::string>& fields) {
  if (!on_) return;
  for (std::size_t i = 0; i < fields.size(); ++i) f_ << (i ? "," : "") << fields[i];
  f_ << "\n";
  f_.flush();
}

}  // namespace pdt_bench
