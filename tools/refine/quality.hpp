// SPDX-License-Identifier: MIT
#pragma once
// Tetrahedron measures a Delaunay refiner judges cells by, in doubles: the
// circumcentre and circumradius, the radius-edge ratio, the dihedral angles.
#include <algorithm>
#include <array>
#include <cmath>

#include "pdt/geometry.hpp"

namespace pdt_refine {

using pdt::Point3;

inline Point3 sub(const Point3& a, const Point3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline double dot(const Point3& a, const Point3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Point3 cross(const Point3& a, const Point3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm2(const Point3& a) { return dot(a, a); }
inline double dist2(const Point3& a, const Point3& b) { return norm2(sub(a, b)); }

struct TetShape {
  Point3 circumcentre;
  double circumradius = 0;
  double shortest_edge = 0;
  double radius_edge = 0;  // circumradius / shortest edge
  // false for a flat tetrahedron (no finite circumsphere), and for one so
  // nearly flat that doubles cannot place its circumcentre: the centre found
  // is not equidistant from the four vertices (to 1e-6 of the radius). Four
  // nearly cocircular, nearly coplanar points make one (a torus's surface
  // samples mirrored across its plane of symmetry did): any sphere through
  // their circle nearly passes through all four, and the centre computed
  // lands anywhere on the circle's axis, so a point inserted there need not
  // be in the tetrahedron's circumsphere at all.
  bool ok = false;
};

// How far the squared distances from a computed circumcentre to the four
// vertices may differ, relative to the squared radius (about 1e-6 of the
// radius), for the centre to count as placed (TetShape::ok).
inline constexpr double placed_tolerance = 2e-6;

// Computed relative to p[0], so the numbers stay small near the tetrahedron.
inline TetShape shape(const std::array<Point3, 4>& p) {
  TetShape s;
  const Point3 a = sub(p[1], p[0]), b = sub(p[2], p[0]), c = sub(p[3], p[0]);
  const double det = 2 * dot(a, cross(b, c));
  if (!(std::fabs(det) > 0)) return s;
  const Point3 num{norm2(a) * cross(b, c).x + norm2(b) * cross(c, a).x + norm2(c) * cross(a, b).x,
                   norm2(a) * cross(b, c).y + norm2(b) * cross(c, a).y + norm2(c) * cross(a, b).y,
                   norm2(a) * cross(b, c).z + norm2(b) * cross(c, a).z + norm2(c) * cross(a, b).z};
  const Point3 o{num.x / det, num.y / det, num.z / det};
  s.circumcentre = {p[0].x + o.x, p[0].y + o.y, p[0].z + o.z};
  s.circumradius = std::sqrt(norm2(o));
  double shortest = HUGE_VAL;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) shortest = std::min(shortest, dist2(p[i], p[j]));
  s.shortest_edge = std::sqrt(shortest);
  s.radius_edge = s.shortest_edge > 0 ? s.circumradius / s.shortest_edge : HUGE_VAL;
  s.ok = std::isfinite(s.circumradius) && std::isfinite(s.radius_edge);
  if (s.ok) {
    // Squared distances from the centre to p[1..3] against the radius's
    // (to p[0]); well-shaped and sliver tetrahedra agree to about 1e-13.
    const double r2 = norm2(o), tolerance = placed_tolerance * r2;
    for (const Point3& v : {a, b, c})
      if (!(std::fabs(dist2(o, v) - r2) <= tolerance)) s.ok = false;
  }
  return s;
}

// The smallest of the six dihedral angles, in degrees. acos decreases, so
// the smallest angle is acos of the largest cosine: one acos, not six (the
// same value).
inline double min_dihedral_degrees(const std::array<Point3, 4>& p) {
  static constexpr int edge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  double largest_cosine = -1;
  for (const auto& e : edge) {
    int o[2], k = 0;
    for (int v = 0; v < 4; ++v)
      if (v != e[0] && v != e[1]) o[k++] = v;
    // The angle between the two faces through edge e: normals of (e0, e1, o0) and (e0, e1, o1).
    const Point3 u = sub(p[e[1]], p[e[0]]);
    Point3 n0 = cross(u, sub(p[o[0]], p[e[0]])), n1 = cross(u, sub(p[o[1]], p[e[0]]));
    const double l = std::sqrt(norm2(n0) * norm2(n1));
    if (!(l > 0)) return 0;
    largest_cosine = std::max(largest_cosine, std::clamp(dot(n0, n1) / l, -1.0, 1.0));
  }
  return std::acos(largest_cosine) * 180 / M_PI;
}

}  // namespace pdt_refine
