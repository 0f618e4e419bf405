// SPDX-License-Identifier: MIT
#include "id_map.hpp"

#include <algorithm>
#include <utility>

namespace pdt::detail {

namespace {
// Fibonacci hashing: the table size is a power of two; the high bits of the
// product are well mixed, so fold them down.
inline std::size_t slot_hash(std::uint64_t key, std::size_t mask) {
  std::uint64_t h = key * 0x9E3779B97F4A7C15ull;
  return static_cast<std::size_t>(h ^ (h >> 32)) & mask;
}
}  // namespace

void IdMap::reserve_for(std::size_t entries) {
  std::size_t want = 16;
  while (want < 2 * entries) want <<= 1;
  if (want <= keys_.size()) return;
  clear();
  keys_.assign(want, empty_key);
  values_.assign(want, 0);
  mask_ = want - 1;
}

void IdMap::clear() {
  for (std::uint32_t s : used_) keys_[s] = empty_key;
  used_.clear();
}

std::uint32_t IdMap::get_or_insert(std::uint64_t key, std::uint32_t value, bool* inserted) {
  if (2 * (used_.size() + 1) > keys_.size()) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> old;
    old.reserve(used_.size());
    for (std::uint32_t s : used_) old.emplace_back(keys_[s], values_[s]);
    std::size_t want = std::max<std::size_t>(16, keys_.size() * 2);
    keys_.assign(want, empty_key);
    values_.assign(want, 0);
    mask_ = want - 1;
    used_.clear();
    for (auto& [k, v] : old) get_or_insert(k, v);
  }
  std::size_t s = slot_hash(key, mask_);
  while (true) {
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
    s = (s + 1) & mask_;
  }
}

std::uint32_t IdMap::find(std::uint64_t key) const {
  if (keys_.empty()) return absent;
  std::size_t s = slot_hash(key, mask_);
  while (true) {
    if (keys_[s] == key) return values_[s];
    if (keys_[s] == empty_key) return absent;
    s = (s + 1) & mask_;
  }
}

}  // namespace pdt::detail
