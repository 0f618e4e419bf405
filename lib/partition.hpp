// SPDX-License-Identifier: MIT
#pragma once
// Partition (paper §3.1, made finer for load balance): the domain box cut into
// b^3 blocks, numbered along a Morton (Z-order) curve, so that a run of
// consecutive numbers is a compact region. Worker w's home is the run
// [home_first(w), home_first(w + 1)); blocks much outnumber workers, so a
// worker can take over part of another's region block by block.
#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

#include "box_lattice.hpp"
#include "pdt/geometry.hpp"

namespace pdt::detail {

class Partition {
 public:
  static constexpr unsigned max_blocks_per_axis = 64;

  Partition(const Box& domain, unsigned blocks_per_axis, unsigned workers)
      : lattice_(corner(domain.lo).c, corner(domain.hi).c, static_cast<int>(blocks_per_axis)),
        b_(blocks_per_axis),
        workers_(workers),
        rank_(std::size_t{blocks_per_axis} * blocks_per_axis * blocks_per_axis) {
    // Rank of each lattice cell along the Morton curve (b need not be a power of two).
    std::vector<std::uint64_t> code(rank_.size());
    for (std::uint32_t z = 0; z < b_; ++z)
      for (std::uint32_t y = 0; y < b_; ++y)
        for (std::uint32_t x = 0; x < b_; ++x) code[cell(x, y, z)] = morton(x, y, z);
    std::vector<std::uint32_t> order(rank_.size());
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return code[a] < code[b]; });
    for (std::uint32_t r = 0; r < order.size(); ++r) rank_[order[r]] = r;
  }

  std::uint32_t blocks() const { return static_cast<std::uint32_t>(rank_.size()); }
  unsigned blocks_per_axis() const { return b_; }
  // The block holding p (points outside the domain go to the nearest block).
  std::uint32_t block_of(const Point3& p) const {
    return rank_[cell(static_cast<std::uint32_t>(lattice_.index(0, p.x)), static_cast<std::uint32_t>(lattice_.index(1, p.y)),
                      static_cast<std::uint32_t>(lattice_.index(2, p.z)))];
  }
  unsigned home_of(std::uint32_t block) const {
    return static_cast<unsigned>(std::uint64_t{block} * workers_ / blocks());
  }
  // The first block of worker w's home (w may be workers(): the end).
  std::uint32_t home_first(unsigned w) const {
    return static_cast<std::uint32_t>((std::uint64_t{w} * blocks() + workers_ - 1) / workers_);
  }

 private:
  struct Corner {
    double c[3];
  };
  static Corner corner(const Point3& p) { return {{p.x, p.y, p.z}}; }
  std::size_t cell(std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
    return (std::size_t{z} * b_ + y) * b_ + x;
  }
  static std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    std::uint64_t key = 0;
    for (int bit = 0; bit < 7; ++bit)
      key |= (std::uint64_t{(x >> bit) & 1u} << (3 * bit)) | (std::uint64_t{(y >> bit) & 1u} << (3 * bit + 1)) |
             (std::uint64_t{(z >> bit) & 1u} << (3 * bit + 2));
    return key;
  }
  BoxLattice lattice_;
  unsigned b_, workers_;
  std::vector<std::uint32_t> rank_;  // lattice cell -> Morton rank (the block number)
};

}  // namespace pdt::detail
