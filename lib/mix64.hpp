// SPDX-License-Identifier: MIT
#pragma once
// A 64-bit mixer (splitmix64's finaliser): seeds and hashes.
#include <cstdint>

namespace pdt::detail {

inline std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  x ^= x >> 31;
  return x;
}

}  // namespace pdt::detail
