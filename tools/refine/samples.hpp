// SPDX-License-Identifier: MIT
#pragma once
// The surface samples of a refinement, indexed by a grid of cells: the
// nearest one within a radius, whether a point is one, and the right to
// insert each one (claimed once, from any thread).
#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <vector>

#include "pdt/geometry.hpp"
#include "refine/quality.hpp"

namespace pdt_refine {

// Samples sorted by grid cell (a cell's samples contiguous, in index order)
// and an open-addressing table from each non-empty cell to its run: a
// lookup is one probe and one contiguous scan. (The first form, a hash map of
// per-cell vectors and a second map for is_sample, was the refiner's hottest
// function.)
//
// Invariant (checked in debug builds by check()): order_ holds every sample
// index once, sorted by (cell key, index); sorted_[j] == pts_[order_[j]];
// each non-empty cell has one table slot whose [begin, end) is exactly its
// run in order_; every other slot is empty (begin == empty_slot); the table's
// size is a power of two, at least twice the non-empty cells.
class Samples {
 public:
  Samples(std::vector<Point3> pts, double cell) : pts_(std::move(pts)), cell_(cell), state_(pts_.size()) {
    std::vector<Key> keys(pts_.size());
    for (std::size_t i = 0; i < pts_.size(); ++i) keys[i] = key(pts_[i]);
    order_.resize(pts_.size());
    for (std::uint32_t i = 0; i < order_.size(); ++i) order_[i] = i;
    std::sort(order_.begin(), order_.end(),
              [&](std::uint32_t a, std::uint32_t b) { return keys[a] != keys[b] ? keys[a] < keys[b] : a < b; });
    sorted_.resize(pts_.size());
    std::size_t runs = 0;
    for (std::size_t j = 0; j < order_.size(); ++j) {
      sorted_[j] = pts_[order_[j]];
      runs += j == 0 || keys[order_[j]] != keys[order_[j - 1]];
    }
    std::size_t size = 16;
    while (size < 2 * runs) size *= 2;
    table_.assign(size, Slot{});
    for (std::size_t j = 0; j < order_.size();) {
      std::size_t e = j + 1;
      while (e < order_.size() && keys[order_[e]] == keys[order_[j]]) ++e;
      Slot& slot = table_[free_slot(keys[order_[j]])];
      slot.key = keys[order_[j]];
      slot.begin = static_cast<std::uint32_t>(j);
      slot.end = static_cast<std::uint32_t>(e);
      j = e;
    }
    assert(check());
  }
  std::size_t size() const { return pts_.size(); }
  const Point3& operator[](std::uint32_t i) const { return pts_[i]; }
  // The nearest sample within r of p, or -1.
  std::int64_t nearest_within(const Point3& p, double r) const { return nearest(p, r, false); }
  // The nearest sample within r of p that nobody has claimed yet, or -1.
  std::int64_t nearest_free_within(const Point3& p, double r) const { return nearest(p, r, true); }
  // Reads the grid cells that the ball (p, r) meets, at most 129 per axis:
  // for the refiner's snap radius (half a cell) 8 of them, not the 27 around
  // p's cell. Of equally near samples, the first in (z, y, x, index) order.
  std::int64_t nearest(const Point3& p, double r, bool free_only) const {
    // Widened so that rounding in p +- r (an ulp of p's largest coordinate,
    // not of r) and in the division by the cell size never drops a cell.
    const double w = r * (1 + 1e-9) + 1e-12 * std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    const Key lo = key({p.x - w, p.y - w, p.z - w}), hi = key({p.x + w, p.y + w, p.z + w}), k = key(p);
    Key from, to;
    for (int a = 0; a < 3; ++a) from[a] = std::max(lo[a], k[a] - 64), to[a] = std::min(hi[a], k[a] + 64);
    std::int64_t best = -1;
    double best_d2 = r * r;
    for (std::int64_t z = from[2]; z <= to[2]; ++z)
      for (std::int64_t y = from[1]; y <= to[1]; ++y)
        for (std::int64_t x = from[0]; x <= to[0]; ++x) {
          const Slot* slot = find({x, y, z});
          if (!slot) continue;
          for (std::uint32_t j = slot->begin; j < slot->end; ++j)
            if (const double d2 = dist2(p, sorted_[j]);
                d2 < best_d2 && (!free_only || state_[order_[j]].load(std::memory_order_relaxed) == 0))
              best_d2 = d2, best = order_[j];
        }
    return best;
  }
  // Whether p is one of the samples (-0.0 equal to 0.0, as ==).
  bool is_sample(const Point3& p) const {
    const Slot* slot = find(key(p));
    if (!slot) return false;
    for (std::uint32_t j = slot->begin; j < slot->end; ++j)
      if (sorted_[j].x == p.x && sorted_[j].y == p.y && sorted_[j].z == p.z) return true;
    return false;
  }
  // The first caller wins the right to insert sample i.
  bool claim(std::uint32_t i) {
    std::uint8_t expect = 0;
    return state_[i].compare_exchange_strong(expect, 1);
  }
  bool check() const {
    if (order_.size() != pts_.size() || sorted_.size() != pts_.size()) return false;
    if (table_.empty() || (table_.size() & (table_.size() - 1)) != 0) return false;
    std::vector<bool> seen(pts_.size(), false);
    std::size_t covered = 0, runs = 0;
    for (std::size_t j = 0; j < order_.size(); ++j) {
      const std::uint32_t i = order_[j];
      if (i >= pts_.size() || seen[i]) return false;
      seen[i] = true;
      if (!(sorted_[j].x == pts_[i].x && sorted_[j].y == pts_[i].y && sorted_[j].z == pts_[i].z)) return false;
      if (j > 0) {
        const Key a = key(pts_[order_[j - 1]]), b = key(pts_[i]);
        if (b < a || (a == b && order_[j - 1] > i)) return false;
      }
    }
    for (const Slot& slot : table_) {
      if (slot.begin == empty_slot) continue;
      ++runs;
      if (slot.begin >= slot.end || slot.end > order_.size() || find(slot.key) != &slot) return false;
      for (std::uint32_t j = slot.begin; j < slot.end; ++j)
        if (key(sorted_[j]) != slot.key) return false;
      if (slot.begin > 0 && key(sorted_[slot.begin - 1]) == slot.key) return false;
      if (slot.end < sorted_.size() && key(sorted_[slot.end]) == slot.key) return false;
      covered += slot.end - slot.begin;
    }
    return covered == pts_.size() && table_.size() >= 2 * runs;
  }

 private:
  using Key = std::array<std::int64_t, 3>;
  static constexpr std::uint32_t empty_slot = 0xFFFFFFFFu;
  struct Slot {
    Key key{};
    std::uint32_t begin = empty_slot, end = empty_slot;
  };
  static std::size_t hash(const Key& k) {
    std::uint64_t h = static_cast<std::uint64_t>(k[0]) * 0x9E3779B97F4A7C15ull;
    h = (h ^ (h >> 29) ^ static_cast<std::uint64_t>(k[1])) * 0xBF58476D1CE4E5B9ull;
    h = (h ^ (h >> 32) ^ static_cast<std::uint64_t>(k[2])) * 0x94D049BB133111EBull;
    return static_cast<std::size_t>(h ^ (h >> 31));
  }
  // The slot of cell k, or null when no sample lies in it.
  const Slot* find(const Key& k) const {
    const std::size_t mask = table_.size() - 1;
    for (std::size_t at = hash(k) & mask;; at = (at + 1) & mask) {
      const Slot& slot = table_[at];
      if (slot.begin == empty_slot) return nullptr;
      // Coordinate by coordinate: the array's == is a call to memcmp here.
      if (slot.key[0] == k[0] && slot.key[1] == k[1] && slot.key[2] == k[2]) return &slot;
    }
  }
  // Where cell k goes while the table is built (k not in it yet).
  std::size_t free_slot(const Key& k) const {
    const std::size_t mask = table_.size() - 1;
    std::size_t at = hash(k) & mask;
    while (table_[at].begin != empty_slot) at = (at + 1) & mask;
    return at;
  }
  Key key(const Point3& p) const {
    return {static_cast<std::int64_t>(std::floor(p.x / cell_)), static_cast<std::int64_t>(std::floor(p.y / cell_)),
            static_cast<std::int64_t>(std::floor(p.z / cell_))};
  }
  std::vector<Point3> pts_;
  double cell_;
  std::vector<std::atomic<std::uint8_t>> state_;  // 0: not inserted; 1: claimed (inserted or on its way)
  std::vector<std::uint32_t> order_;              // sample indices by (cell, index)
  std::vector<Point3> sorted_;                    // their points, in that order
  std::vector<Slot> table_;                       // non-empty cell -> its run [begin, end) in order_
};

}  // namespace pdt_refine
