// SPDX-License-Identifier: MIT
#pragma once
// Partition (paper §3.1, made finer and adaptive for load balance): the domain
// box ordered along a fine Morton (Z-order) curve, 2^16 cells per axis, and
// the curve cut into `blocks()` intervals. Block i holds the points whose key
// lies in [split(i), split(i + 1)), so consecutive blocks are mostly
// neighbouring regions (a Z-curve jumps now and then). Worker w's home is the run of blocks [home_first(w),
// home_first(w + 1)); blocks much outnumber workers, so a worker can take over
// part of another's region block by block.
//
// The engine starts from intervals of equal length (equal volumes), and when
// work piles up where only a few blocks are (a cluster, a front), it re-cuts
// the curve at quantiles of the queued operations' keys (`recut`), so that each
// block, and so each home, holds about the same amount of work.
//
// Blocks only route work: correctness never depends on them (the vertex locks
// do). So `block_of` may run concurrently with `recut`: it reads each split
// atomically and, during a recut, may see a mix of old and new splits; it
// still returns a valid block, only maybe not the best one.
// Invariant (checked in debug builds after every cut): split(0) = 0,
// split(blocks()) = key_end, and the splits never decrease.
#include <algorithm>
#include <atomic>
#include <cassert>
#include <cstdint>
#include <memory>
#include <span>

#include "box_lattice.hpp"
#include "pdt/geometry.hpp"

namespace pdt::detail {

class Partition {
 public:
  static constexpr unsigned max_blocks_per_axis = 64;
  static constexpr int key_bits_per_axis = 16;
  static constexpr std::uint64_t key_end = std::uint64_t{1} << (3 * key_bits_per_axis);

  Partition(const Box& domain, unsigned blocks_per_axis, unsigned workers)
      : lattice_(corner(domain.lo).c, corner(domain.hi).c, 1 << key_bits_per_axis),
        b_(blocks_per_axis),
        count_(blocks_per_axis * blocks_per_axis * blocks_per_axis),
        workers_(workers),
        split_(std::make_unique<std::atomic<std::uint64_t>[]>(count_ + 1)) {
    for (std::uint32_t i = 0; i <= count_; ++i)
      split_[i].store(static_cast<std::uint64_t>(key_end / count_ * i + key_end % count_ * i / count_),
                      std::memory_order_relaxed);
    assert(check());
  }

  std::uint32_t blocks() const { return count_; }
  unsigned blocks_per_axis() const { return b_; }

  // The point's place on the curve (points outside the domain go to the nearest cell).
  std::uint64_t key_of(const Point3& p) const {
    return morton(static_cast<std::uint32_t>(lattice_.index(0, p.x)), static_cast<std::uint32_t>(lattice_.index(1, p.y)),
                  static_cast<std::uint32_t>(lattice_.index(2, p.z)));
  }
  // The block holding key: the last i with split(i) <= key.
  std::uint32_t block_of_key(std::uint64_t key) const {
    std::uint32_t lo = 0, hi = count_;  // split(lo) <= key < split(hi), if the splits are in order
    while (hi - lo > 1) {
      const std::uint32_t mid = lo + (hi - lo) / 2;
      if (split_[mid].load(std::memory_order_relaxed) <= key)
        lo = mid;
      else
        hi = mid;
    }
    return lo;
  }
  std::uint32_t block_of(const Point3& p) const { return block_of_key(key_of(p)); }
  // The same, trying `near` (a block, or blocks() for none) first: points
  // along a curve mostly stay in the block of the one before them, and then
  // no search is made.
  std::uint32_t block_of(const Point3& p, std::uint32_t near) const {
    const std::uint64_t key = key_of(p);
    if (near < count_ && split_[near].load(std::memory_order_relaxed) <= key &&
        key < split_[near + 1].load(std::memory_order_relaxed))
      return near;
    return block_of_key(key);
  }

  // Re-cuts the curve so that each block gets an equal share of `sorted_keys`
  // (a sample of where the work is, in increasing order; not empty).
  void recut(std::span<const std::uint64_t> sorted_keys) {
    assert(!sorted_keys.empty() && std::is_sorted(sorted_keys.begin(), sorted_keys.end()));
    const std::size_t n = sorted_keys.size();
    for (std::uint32_t i = 1; i < count_; ++i)
      split_[i].store(sorted_keys[static_cast<std::size_t>(std::uint64_t{i} * n / count_)], std::memory_order_relaxed);
    assert(check());
  }

  unsigned home_of(std::uint32_t block) const {
    return static_cast<unsigned>(std::uint64_t{block} * workers_ / count_);
  }
  // The first block of worker w's home (w may be workers(): the end).
  std::uint32_t home_first(unsigned w) const {
    return static_cast<std::uint32_t>((std::uint64_t{w} * count_ + workers_ - 1) / workers_);
  }

 private:
  struct Corner {
    double c[3];
  };
  static Corner corner(const Point3& p) { return {{p.x, p.y, p.z}}; }
  static std::uint64_t spread(std::uint32_t v) {  // bit k of v to bit 3k
    std::uint64_t x = v & 0xffffu;
    x = (x | (x << 16)) & 0x0000ff0000ffULL;
    x = (x | (x << 8)) & 0x00f00f00f00fULL;
    x = (x | (x << 4)) & 0x0c30c30c30c3ULL;
    x = (x | (x << 2)) & 0x249249249249ULL;
    return x;
  }
  static std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return spread(x) | (spread(y) << 1) | (spread(z) << 2);
  }
  bool check() const {
    if (split_[0].load() != 0 || split_[count_].load() != key_end) return false;
    for (std::uint32_t i = 0; i < count_; ++i)
      if (split_[i].load() > split_[i + 1].load()) return false;
    return true;
  }
  BoxLattice lattice_;
  unsigned b_;
  std::uint32_t count_;
  unsigned workers_;
  std::unique_ptr<std::atomic<std::uint64_t>[]> split_;  // count_ + 1 keys, in order
};

}  // namespace pdt::detail
