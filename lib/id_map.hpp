// SPDX-License-Identifier: MIT
#pragma once
// IdMap: uint64 -> uint32 open-addressing map, cleared in O(entries used).
// Scratch for one operation: no allocation once warmed up.
//
// Invariant: keys_.size() is a power of two (or 0) and more than twice the
// entries; used_ lists exactly the slots whose key is not empty_key.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace pdt::detail {

class IdMap {
 public:
  static constexpr std::uint32_t absent = 0xFFFFFFFFu;
  void clear();
  // Returns the value for key, inserting `value` if absent (then *inserted = true).
  std::uint32_t get_or_insert(std::uint64_t key, std::uint32_t value, bool* inserted = nullptr) {
    if (2 * (used_.size() + 1) > keys_.size()) grow();
    for (std::size_t s = slot_hash(key, mask_);; s = (s + 1) & mask_) {
      if (keys_[s] == key) {
        if (inserted) *inserted = false;
        return values_[s];
      }
      if (keys_[s] == empty_key) {
        keys_[s] = key;
        values_[s] = value;
        used_.push_back(static_cast<std::uint32_t>(s));
        if (inserted) *inserted = true;
        return value;
      }
    }
  }
  std::uint32_t find(std::uint64_t key) const {  // absent if absent
    if (keys_.empty()) return absent;
    for (std::size_t s = slot_hash(key, mask_);; s = (s + 1) & mask_) {
      if (keys_[s] == key) return values_[s];
      if (keys_[s] == empty_key) return absent;
    }
  }
  // Makes room for `entries` without rehashing; may clear the map.
  void reserve_for(std::size_t entries);
  std::size_t slots() const { return keys_.size(); }
  // Frees the table (between operations: the entries are lost); the next
  // insertion grows it again.
  void release() { *this = IdMap(); }

 private:
  static constexpr std::uint64_t empty_key = ~std::uint64_t{0};
  // Fibonacci hashing: the table size is a power of two; the high bits of
  // the product are well mixed, so fold them down.
  static std::size_t slot_hash(std::uint64_t key, std::size_t mask) {
    const std::uint64_t h = key * 0x9E3779B97F4A7C15ull;
    return static_cast<std::size_t>(h ^ (h >> 32)) & mask;
  }
  void grow();  // doubles the table (at least 16 slots), keeping the entries
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::vector<std::uint32_t> used_;
  std::size_t mask_ = 0;
};

}  // namespace pdt::detail
