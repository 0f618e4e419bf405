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
  std::uint32_t get_or_insert(std::uint64_t key, std::uint32_t value, bool* inserted = nullptr);
  std::uint32_t find(std::uint64_t key) const;  // absent if absent
  // Makes room for `entries` without rehashing; may clear the map.
  void reserve_for(std::size_t entries);

 private:
  static constexpr std::uint64_t empty_key = ~std::uint64_t{0};
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::vector<std::uint32_t> used_;
  std::size_t mask_ = 0;
};

}  // namespace pdt::detail
