// SPDX-License-Identifier: MIT
#pragma once
// The checks and messages every entry point applies to user points and boxes,
// written once: which coordinates pdt accepts, and how a point or a box is
// printed in an error message (17 significant digits: the exact double).
#include <string>

#include "pdt/geometry.hpp"

namespace pdt::detail {

bool is_finite(const Point3& p);
std::string format_point(const Point3& p);  // "(x, y, z)"
std::string format_box(const Box& b);       // "[x0, x1] x [y0, y1] x [z0, z1]"

// Throws pdt::Error(non_finite_coordinate) naming the point.
void require_finite(const Point3& p);
// Why a box cannot be a domain (a non-finite corner, lo > hi on an axis), or
// nullptr when it can.
const char* box_problem(const Box& b);
// Throws pdt::Error(outside_domain) naming the point and the domain.
void require_inside(const Point3& p, const Box& domain);

}  // namespace pdt::detail
