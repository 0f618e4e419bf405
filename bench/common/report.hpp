// SPDX-License-Identifier: MIT
#pragma once
// The benches' output: tables with per-thread-count columns, number
// formatting, and a CSV writer (one row per measurement) for plots.
#include <cstdint>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace pdt_bench {

// A table with a label column and groups of per-thread-count columns.
class Table {
 public:
  Table(std::vector<std::string> groups, std::vector<unsigned> threads)
      : groups_(std::move(groups)), threads_(std::move(threads)) {}
  // cells: groups.size() * threads.size() strings, group-major.
  void add(const std::string& label, std::vector<std::string> cells) { rows_.push_back({label, std::move(cells)}); }
  // Adds a row whose cell for group g and thread-count index i is cell(g, i).
  template <class Cell>
  void row(const std::string& label, Cell cell) {
    std::vector<std::string> cells;
    for (std::size_t g = 0; g < groups_.size(); ++g)
      for (std::size_t i = 0; i < threads_.size(); ++i) cells.push_back(cell(static_cast<int>(g), i));
    add(label, std::move(cells));
  }
  void print() const;

 private:
  std::vector<std::string> groups_;
  std::vector<unsigned> threads_;
  std::vector<std::pair<std::string, std::vector<std::string>>> rows_;
};

std::string fmt(const char* f, double v);
std::string fmt_u(std::uint64_t v);
// num / den as "%.2f"; "-" when either is not positive (a phase with no operations).
std::string fmt_ratio(double num, double den);

// CSV: a header, then rows; flushed per row, so a run that dies keeps its rows.
class CsvWriter {
 public:
  // No file (path empty): rows are dropped. Throws pdt::Error(io_failure).
  CsvWriter(const std::string& path, const std::string& header);
  bool on() const { return on_; }
  void row(const std::vector<std::string>& fields);

 private:
  std::ofstream f_;
  bool on_ = false;
};

}  // namespace pdt_bench
