#pragma once
// A point of R^3 as the user gives it. Coordinates are IEEE doubles and are
// used exactly: no rounding, scaling or snapping happens anywhere in pdt.
namespace pdt {

struct Point3 {
  double x = 0, y = 0, z = 0;
  friend bool operator==(const Point3&, const Point3&) = default;
};

}  // namespace pdt
