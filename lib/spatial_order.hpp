// SPDX-License-Identifier: MIT
#pragma once
// The order in which a batch of points is inserted: a biased randomized
// insertion order (BRIO) whose rounds follow a Hilbert curve, so that
// consecutive points are close and each walk starts next to its target. The
// rounds are CGAL's spatial_sort's (its range insertion's order); the curve
// is computed on 21-bit keys per axis over the points' bounding box, and
// CGAL's own median-split sort takes over where those keys cannot tell the
// points apart (a cluster far smaller than the box).
#include <cstdint>
#include <span>
#include <vector>

#include "pdt/geometry.hpp"

namespace pdt::detail {

// A permutation of 0..points.size()-1, the same on every run and for either
// value of parallel (with the keys; CGAL's fallback may differ between the
// two). parallel: keys and sort with oneTBB in the caller's arena. Points
// must be finite.
std::vector<std::uint32_t> spatial_order(std::span<const Point3> points, bool parallel);

// The order's rounds, as CGAL's: the round ending at `end` begins at
// brio_round_begin(end): the last 3/4 of the range, down to 16 points (the
// first round then holds the rest). spatial_order sorts these rounds.
inline std::size_t brio_round_begin(std::size_t end) { return end >= 16 ? end / 4 : 0; }

// The round of the order's position k (< n) among n points: 0 for the last
// round, [n / 4, n), 1 for the one before it, and so on (CGAL's fallback
// order cuts about the same places).
inline unsigned brio_round(std::size_t k, std::size_t n) {
  unsigned round = 0;
  for (std::size_t end = n; k < brio_round_begin(end); end = brio_round_begin(end)) ++round;
  return round;
}

}  // namespace pdt::detail
