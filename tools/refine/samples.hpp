// SPDX-License-Identifier: MIT
#pragma once
// The surface samples of a refinement, indexed by a grid of cells: the
// nearest one within a radius, whether a point is one, and the right to
// insert each one (claimed once, from any thread).
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <unordered_map>
#include <vector>

#include "pdt/geometry.hpp"
#include "refine/quality.hpp"

namespace pdt_refine {

class Samples {
 public:
  Samples(std::vector<Point3> pts, double cell) : pts_(std::move(pts)), cell_(cell), state_(pts_.size()) {
    for (std::uint32_t i = 0; i < pts_.size(); ++i) {
      grid_[key(pts_[i])].push_back(i);
      index_.emplace(pts_[i], i);
    }
  }
  std::size_t size() const { return pts_.size(); }
  const Point3& operator[](std::uint32_t i) const { return pts_[i]; }
  // The nearest sample within r of p, or -1.
  std::int64_t nearest_within(const Point3& p, double r) const { return nearest(p, r, false); }
  // The nearest sample within r of p that nobody has claimed yet, or -1.
  std::int64_t nearest_free_within(const Point3& p, double r) const { return nearest(p, r, true); }
  // Reads the grid cells that the ball (p, r) meets, at most 129 per axis:
  // for the refiner's snap radius (half a cell) 8 of them, not the 27 around
  // p's cell (those lookups were the refiner's hottest function).
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
          auto it = grid_.find({x, y, z});
          if (it == grid_.end()) continue;
          for (std::uint32_t i : it->second)
            if (const double d2 = dist2(p, pts_[i]);
                d2 < best_d2 && (!free_only || state_[i].load(std::memory_order_relaxed) == 0))
              best_d2 = d2, best = i;
        }
    return best;
  }
  bool is_sample(const Point3& p) const { return index_.count(p) != 0; }
  // The first caller wins the right to insert sample i.
  bool claim(std::uint32_t i) {
    std::uint8_t expect = 0;
    return state_[i].compare_exchange_strong(expect, 1);
  }

 private:
  using Key = std::array<std::int64_t, 3>;
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      return static_cast<std::size_t>(k[0] * 73856093 ^ k[1] * 19349663 ^ k[2] * 83492791);
    }
  };
  struct PointHash {
    std::size_t operator()(const Point3& p) const {
      std::size_t h = std::hash<double>()(p.x);
      h ^= std::hash<double>()(p.y) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
      return h ^ (std::hash<double>()(p.z) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2));
    }
  };
  Key key(const Point3& p) const {
    return {static_cast<std::int64_t>(std::floor(p.x / cell_)), static_cast<std::int64_t>(std::floor(p.y / cell_)),
            static_cast<std::int64_t>(std::floor(p.z / cell_))};
  }
  std::vector<Point3> pts_;
  double cell_;
  std::vector<std::atomic<std::uint8_t>> state_;  // 0: not inserted; 1: claimed (inserted or on its way)
  std::unordered_map<Key, std::vector<std::uint32_t>, KeyHash> grid_;
  std::unordered_map<Point3, std::uint32_t, PointHash> index_;
};

}  // namespace pdt_refine
