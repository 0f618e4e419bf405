// SPDX-License-Identifier: MIT
#pragma once
// Point sets the tests build from: generated distributions, the degenerate
// integer lattice and exactly cospherical sets, bounding boxes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "pdt/generate.hpp"
#include "pdt/geometry.hpp"

namespace pdt_test {

// The inserted points of pdt::generate's stream for these options (in order).
inline std::vector<pdt::Point3> generated_points(pdt::Distribution dist, std::uint64_t n, std::uint64_t seed) {
  pdt::GenerateOptions o;
  o.dist = dist;
  o.points = n;
  o.seed = seed;
  pdt::OpStream s = pdt::generate(o);
  std::vector<pdt::Point3> pts;
  for (const auto& op : s.ops)
    if (op.kind == pdt::Operation::Kind::insert) pts.push_back(op.point);
  return pts;
}

// {0..n-1}^3: many cospherical and coplanar subsets.
inline std::vector<pdt::Point3> lattice(int n) {
  std::vector<pdt::Point3> pts;
  for (int x = 0; x < n; ++x)
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z) pts.push_back({double(x), double(y), double(z)});
  return pts;
}

// Every integer point with x^2 + y^2 + z^2 == r2: all exactly cospherical.
inline std::vector<pdt::Point3> cospherical(int r2) {
  std::vector<pdt::Point3> pts;
  const int r = static_cast<int>(std::sqrt(double(r2))) + 1;
  for (int x = -r; x <= r; ++x)
    for (int y = -r; y <= r; ++y)
      for (int z = -r; z <= r; ++z)
        if (x * x + y * y + z * z == r2) pts.push_back({double(x), double(y), double(z)});
  return pts;
}

inline pdt::Box bounding_box(const std::vector<pdt::Point3>& pts) {
  pdt::Box b{pts.front(), pts.front()};
  for (const auto& p : pts) {
    b.lo = {std::min(b.lo.x, p.x), std::min(b.lo.y, p.y), std::min(b.lo.z, p.z)};
    b.hi = {std::max(b.hi.x, p.x), std::max(b.hi.y, p.y), std::max(b.hi.z, p.z)};
  }
  return b;
}

}  // namespace pdt_test
