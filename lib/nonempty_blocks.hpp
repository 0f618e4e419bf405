// SPDX-License-Identifier: MIT
#pragma once
// NonEmptyBlocks: which blocks may hold queued operations, one bit per block,
// so that a worker looking for work reads one word per 64 blocks rather than
// every block (with 4096 workers the partition has 64^3 blocks, and idle
// workers scanning them all took seconds per thousand operations).
//
// Invariant: after a push into block i has counted itself in the block's
// `queued` and then called mark(i), bit i stays set until a scanner sees
// `queued` at 0: clear_if_empty clears the bit, then reads the count again and
// sets the bit back if work came in meanwhile. Every access is seq_cst, so of
// a marker (count, then bit) and a clearer (bit, then count) one sees the
// other's write: either the clearer's second look sees the new count, or the
// marker finds the bit cleared and sets it. A set bit on an empty block is
// allowed (a scanner clears it when it passes). Checked with the world
// stopped in debug builds (EngineState::maybe_recut).
// A third party may see the bit clear for a moment while work is queued
// (between a clearer's clear and its set-back). That is safe because the
// only clearer is a running worker in claim() (keep it so): after setting
// the bit back it scans again before it can go idle or sleep (IdleAwait's
// last look at work_for), so the work is never left with nobody to see it.
#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>

namespace pdt::detail {

class NonEmptyBlocks {
 public:
  explicit NonEmptyBlocks(std::uint32_t blocks)
      : words_(std::make_unique<std::atomic<std::uint64_t>[]>((std::size_t{blocks} + 63) / 64)),
        nwords_((std::size_t{blocks} + 63) / 64) {}

  // After block i's count went up.
  void mark(std::uint32_t i) {
    std::atomic<std::uint64_t>& w = words_[i >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (i & 63);
    if (!(w.load() & bit)) w.fetch_or(bit);  // a set bit stays set until its block's count is 0
  }

  // A scanner found block i's count at 0 (`queued`: that count).
  void clear_if_empty(std::uint32_t i, const std::atomic<std::uint32_t>& queued) {
    std::atomic<std::uint64_t>& w = words_[i >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (i & 63);
    if (!(w.load() & bit)) return;  // cleared already (a marker sets it after its count)
    w.fetch_and(~bit);
    if (queued.load() != 0) w.fetch_or(bit);  // work came in meanwhile
  }

  bool marked(std::uint32_t i) const { return (words_[i >> 6].load() >> (i & 63)) & 1; }

  // The first marked block in [from, end), or end.
  std::uint32_t next(std::uint32_t from, std::uint32_t end) const {
    if (from >= end) return end;
    std::size_t word = from >> 6;
    std::uint64_t bits = words_[word].load() & (~std::uint64_t{0} << (from & 63));
    while (!bits) {
      if (++word >= nwords_ || word * 64 >= end) return end;
      bits = words_[word].load();
    }
    const std::uint64_t i = word * 64 + static_cast<unsigned>(std::countr_zero(bits));
    return i < end ? static_cast<std::uint32_t>(i) : end;
  }

  // The last marked block in [0, from], or -1.
  std::int64_t prev(std::int64_t from) const {
    if (from < 0) return -1;
    std::size_t word = static_cast<std::size_t>(from) >> 6;
    const unsigned top = static_cast<unsigned>(from & 63);
    std::uint64_t bits = words_[word].load() & (top == 63 ? ~std::uint64_t{0} : (std::uint64_t{2} << top) - 1);
    while (!bits) {
      if (word == 0) return -1;
      bits = words_[--word].load();
    }
    return static_cast<std::int64_t>(word * 64 + 63 - static_cast<unsigned>(std::countl_zero(bits)));
  }

 private:
  std::unique_ptr<std::atomic<std::uint64_t>[]> words_;  // bit i of word k: block 64k + i
  std::size_t nwords_;
};

}  // namespace pdt::detail
