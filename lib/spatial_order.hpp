// SPDX-License-Identifier: MIT
#pragma once
// The order in which a batch of points is inserted: CGAL's spatial sort
// (Hilbert curve over a biased randomized insertion order, BRIO), so that
// consecutive points are close and each walk starts next to its target, the
// order CGAL's own range insertion uses.
#include <cstdint>
#include <span>
#include <vector>

#include "pdt/geometry.hpp"

namespace pdt::detail {

// A permutation of 0..points.size()-1. parallel: sort with oneTBB in the
// caller's arena. Points must be finite.
std::vector<std::uint32_t> spatial_order(std::span<const Point3> points, bool parallel);

}  // namespace pdt::detail
