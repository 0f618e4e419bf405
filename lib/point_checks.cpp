// SPDX-License-Identifier: MIT
#include "point_checks.hpp"

#include <cmath>

#include "io_util.hpp"
#include "pdt/error.hpp"

namespace pdt::detail {

bool is_finite(const Point3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

std::string format_point(const Point3& p) {
  std::string s = "(";
  append_double(s, p.x);
  s += ", ";
  append_double(s, p.y);
  s += ", ";
  append_double(s, p.z);
  s += ")";
  return s;
}

std::string format_box(const Box& b) {
  std::string s = "[";
  const double lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
  for (int a = 0; a < 3; ++a) {
    if (a) s += "] x [";
    append_double(s, lo[a]);
    s += ", ";
    append_double(s, hi[a]);
  }
  s += "]";
  return s;
}

void require_finite(const Point3& p) {
  if (is_finite(p)) return;
  throw Error(ErrorCode::non_finite_coordinate,
              "point " + format_point(p) + " has a NaN or infinite coordinate; every coordinate must be a finite double");
}

const char* box_problem(const Box& b) {
  // Each coordinate on its own: a sum would overflow for a box near +-DBL_MAX.
  if (!is_finite(b.lo) || !is_finite(b.hi)) return "has a non-finite coordinate";
  if (b.lo.x > b.hi.x || b.lo.y > b.hi.y || b.lo.z > b.hi.z) return "has a lower corner above its upper corner";
  return nullptr;
}

void require_inside(const Point3& p, const Box& domain) {
  if (domain.contains(p)) return;
  throw Error(ErrorCode::outside_domain, "point " + format_point(p) + " is outside the engine's domain " +
                                             format_box(domain) +
                                             "; declare a box that holds every point the refiner may insert");
}

}  // namespace pdt::detail
