// SPDX-License-Identifier: MIT
#pragma once
// Points and boxes as the user gives them. Coordinates are IEEE doubles and
// are used exactly: no rounding, scaling or snapping happens anywhere in pdt.
namespace pdt {

struct Point3 {
  double x = 0, y = 0, z = 0;
  friend bool operator==(const Point3&, const Point3&) = default;
};

// An axis-aligned box, closed: lo and hi are inside.
struct Box {
  Point3 lo, hi;
  bool contains(const Point3& p) const {
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
  }
};

}  // namespace pdt
