// SPDX-License-Identifier: MIT
#include "id_map.hpp"

#include <algorithm>
#include <utility>

namespace pdt::detail {

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

void IdMap::grow() {
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

}  // namespace pdt::detail
