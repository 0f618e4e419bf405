// SPDX-License-Identifier: MIT
#pragma once
// Deletion from a linear-probing table by backward shift, shared by the
// open-addressing sets (FlatIndex, LiveInsertions): no tombstones, so a
// lookup stops at the first empty slot however many erasures came before.
//
// Precondition: slots.size() is a power of two, slot s holds an entry, and
// every entry is reachable from its home slot without crossing an empty one.
// Postcondition: the same, without the entry that was at s.
#include <cstddef>
#include <vector>

namespace pdt::detail {

template <class Slot, class HomeOf>
void erase_by_backward_shift(std::vector<Slot>& slots, std::size_t s, Slot empty, HomeOf home_of) {
  const std::size_t mask = slots.size() - 1;
  // Move later entries of the cluster into the hole when their home does not
  // lie (cyclically) between the hole and them.
  std::size_t hole = s;
  for (std::size_t t = (s + 1) & mask; slots[t] != empty; t = (t + 1) & mask) {
    const std::size_t h = home_of(slots[t]);
    const bool stays = hole <= t ? (hole < h && h <= t) : (hole < h || h <= t);
    if (stays) continue;
    slots[hole] = slots[t];
    hole = t;
  }
  slots[hole] = empty;
}

}  // namespace pdt::detail
