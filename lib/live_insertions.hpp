// SPDX-License-Identifier: MIT
#pragma once
// LiveInsertions: which insertions of an operation stream are live (made and
// not yet undone), so that 'r k' can be checked as a stream is read or
// written. The readers promise memory that follows the live insertions, not
// the stream's length; the writer (a refiner's trace, written inside its
// change hook) wants no allocation per operation. Both are met by a set of
// the live indices by open addressing: linear probing on a Fibonacci hash,
// deletion by backward shift, the table doubled when half full (16 to 32
// bytes per live insertion at the most live there have been).
//
// Invariant: slots_.size() is 0 or a power of two at least twice live_; the
// slots hold exactly the live indices (each k < made_, each once), every one
// reachable from its home slot without crossing an empty one (~0).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "open_addressing.hpp"

namespace pdt::detail {

class LiveInsertions {
 public:
  enum class Undo { done, not_made_yet, already_undone };

  std::uint64_t made() const { return made_; }
  std::size_t live() const { return live_; }
  std::size_t table_bytes() const { return slots_.capacity() * sizeof(std::uint64_t); }

  bool is_live(std::uint64_t k) const {
    if (k >= made_ || slots_.empty()) return false;
    for (std::size_t s = home(k);; s = (s + 1) & mask()) {
      if (slots_[s] == k) return true;
      if (slots_[s] == empty) return false;
    }
  }
  // Records insertion made(). May throw std::bad_alloc; then nothing changed.
  void insert() {
    if (2 * (live_ + 1) > slots_.size()) grow();
    place(made_);
    ++made_;
    ++live_;
  }
  // Undoes insertion k if it is live; else says why not, changing nothing.
  Undo remove(std::uint64_t k) {
    if (k >= made_) return Undo::not_made_yet;
    if (slots_.empty()) return Undo::already_undone;
    std::size_t s = home(k);
    while (slots_[s] != k) {
      if (slots_[s] == empty) return Undo::already_undone;
      s = (s + 1) & mask();
    }
    erase_by_backward_shift(slots_, s, empty, [this](std::uint64_t key) { return home(key); });
    --live_;
    return Undo::done;
  }

 private:
  static constexpr std::uint64_t empty = ~std::uint64_t{0};  // never an index: made_ stops below it
  std::size_t mask() const { return slots_.size() - 1; }
  // Fibonacci hashing. (Keeping runs of consecutive indices in consecutive
  // slots, for the cache, made linear probing's clusters run into each other:
  // pdt run 20-30% slower.)
  std::size_t home(std::uint64_t k) const {
    const std::uint64_t h = k * 0x9E3779B97F4A7C15ull;
    return static_cast<std::size_t>(h ^ (h >> 32)) & mask();
  }
  void place(std::uint64_t k) {
    std::size_t s = home(k);
    while (slots_[s] != empty) s = (s + 1) & mask();
    slots_[s] = k;
  }
  void grow() {
    std::vector<std::uint64_t> bigger(slots_.empty() ? 16 : 2 * slots_.size(), empty);  // may throw: unchanged
    bigger.swap(slots_);
    for (std::uint64_t k : bigger)
      if (k != empty) place(k);
  }

  std::vector<std::uint64_t> slots_;
  std::uint64_t made_ = 0;
  std::size_t live_ = 0;
};

}  // namespace pdt::detail
