// SPDX-License-Identifier: MIT
#pragma once
// Exact geometric predicates (CGAL's filtered Epick kernel) and the symbolic
// perturbation that makes the Delaunay triangulation of any point set unique.
//
// The perturbation is Devillers & Teillaud's ("Perturbations and vertex removal
// in a 3D Delaunay triangulation", SODA 2003), exactly as CGAL's
// Delaunay_triangulation_3 applies it: when an in-sphere test is exactly zero,
// the 5 points are ordered lexicographically (compare_xyz) and, from the largest
// down, the first non-vanishing term of the perturbed determinant decides. Using
// the same rule at insertion and removal makes pdt's result identical to CGAL's.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "pdt/geometry.hpp"

namespace pdt::detail {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using KPoint = Kernel::Point_3;

// A user's point as the kernel stores it: +0.0 turns -0.0 into +0.0, so
// equal points have equal bits.
inline KPoint to_kpoint(const Point3& p) { return KPoint(p.x + 0.0, p.y + 0.0, p.z + 0.0); }

inline int orient(const KPoint& a, const KPoint& b, const KPoint& c, const KPoint& d) {
  return static_cast<int>(CGAL::orientation(a, b, c, d));
}

// The tests below, with an epsilon from a BoxFilter (box_filter.hpp, where
// the bound is argued) for a box holding all their points: CGAL's
// determinant, in CGAL's order, decides when it is beyond eps. Otherwise
// (points close together in a large box, e.g. inside a cluster) the same
// determinant goes on to CGAL's own semi-static bound, computed from the
// call's coordinate differences exactly as CGAL's static filter computes it
// (Static_filters/Orientation_3.h, Side_of_oriented_sphere_3.h): what CGAL
// would decide there, without evaluating the determinant again. Only when
// that bound does not decide either (and for eps = infinity: no box) does
// CGAL's predicate run whole (its static filter again, then interval, then
// exact arithmetic). Out of line, so that the filtered forms stay small
// enough to inline.
[[gnu::noinline]] inline int orient_out_of_line(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s) {
  return orient(p, q, r, s);
}
[[gnu::noinline]] inline int side_of_sphere_out_of_line(const KPoint& p, const KPoint& q, const KPoint& r,
                                                        const KPoint& s, const KPoint& t) {
  return static_cast<int>(CGAL::side_of_oriented_sphere(p, q, r, s, t));
}

// Sorts three non-negative maxima so that lo <= mid <= hi, as CGAL's static
// filters do before their range checks.
inline void sort3(double& lo, double& mid, double& hi) {
  if (lo > hi) std::swap(lo, hi);
  if (mid > hi)
    std::swap(mid, hi);
  else if (mid < lo)
    std::swap(lo, mid);
}

// CGAL::orientation(p, q, r, s), given det: CGAL's determinant of the
// differences from p (bitwise CGAL's: the same operations in the same order).
[[gnu::noinline]] inline int orient_semi_static(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s,
                                                double det) {
  double mx = std::max({std::abs(q.x() - p.x()), std::abs(r.x() - p.x()), std::abs(s.x() - p.x())});
  double my = std::max({std::abs(q.y() - p.y()), std::abs(r.y() - p.y()), std::abs(s.y() - p.y())});
  double mz = std::max({std::abs(q.z() - p.z()), std::abs(r.z() - p.z()), std::abs(s.z() - p.z())});
  const double eps = 5.1107127829973299e-15 * mx * my * mz;
  sort3(mx, my, mz);
  if (mx >= 1e-97 && mz < 1e102) {  // CGAL's underflow and overflow guards
    if (det > eps) return 1;
    if (det < -eps) return -1;
  }
  return orient(p, q, r, s);
}

// CGAL::side_of_oriented_sphere(p, q, r, s, t), given det: CGAL's
// determinant of the differences from t (bitwise CGAL's, as above).
[[gnu::noinline]] inline int side_of_sphere_semi_static(const KPoint& p, const KPoint& q, const KPoint& r,
                                                        const KPoint& s, const KPoint& t, double det) {
  double mx = std::max({std::abs(p.x() - t.x()), std::abs(q.x() - t.x()), std::abs(r.x() - t.x()),
                        std::abs(s.x() - t.x())});
  double my = std::max({std::abs(p.y() - t.y()), std::abs(q.y() - t.y()), std::abs(r.y() - t.y()),
                        std::abs(s.y() - t.y())});
  double mz = std::max({std::abs(p.z() - t.z()), std::abs(q.z() - t.z()), std::abs(r.z() - t.z()),
                        std::abs(s.z() - t.z())});
  double eps = 1.2466136531027298e-13 * mx * my * mz;
  sort3(mx, my, mz);
  if (mx >= 1e-58 && mz < 1e61) {  // CGAL's underflow and overflow guards
    eps *= mz * mz;
    if (det > eps) return 1;
    if (det < -eps) return -1;
  }
  return static_cast<int>(CGAL::side_of_oriented_sphere(p, q, r, s, t));
}

// CGAL::orientation(p, q, r, s).
inline int filtered_orient(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s, double eps) {
  if (!(eps < std::numeric_limits<double>::infinity())) return orient_out_of_line(p, q, r, s);
  // Static_filters/Orientation_3.h: the same differences, the same determinant.
  const double pqx = q.x() - p.x(), pqy = q.y() - p.y(), pqz = q.z() - p.z();
  const double prx = r.x() - p.x(), pry = r.y() - p.y(), prz = r.z() - p.z();
  const double psx = s.x() - p.x(), psy = s.y() - p.y(), psz = s.z() - p.z();
  const double det = CGAL::determinant(pqx, pqy, pqz, prx, pry, prz, psx, psy, psz);
  if (det > eps) return 1;
  if (det < -eps) return -1;
  return orient_semi_static(p, q, r, s, det);
}

// The determinant of CGAL's static filter for side_of_oriented_sphere(p, q,
// r, s, t) (Static_filters/Side_of_oriented_sphere_3.h): the same
// differences and squared norms, the same determinant (rows p, r, q, s), so
// the box's epsilon bounds its rounding error (box_filter.hpp).
inline double side_of_sphere_det(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s,
                                 const KPoint& t) {
  const double ptx = p.x() - t.x(), pty = p.y() - t.y(), ptz = p.z() - t.z();
  const double pt2 = CGAL::square(ptx) + CGAL::square(pty) + CGAL::square(ptz);
  const double qtx = q.x() - t.x(), qty = q.y() - t.y(), qtz = q.z() - t.z();
  const double qt2 = CGAL::square(qtx) + CGAL::square(qty) + CGAL::square(qtz);
  const double rtx = r.x() - t.x(), rty = r.y() - t.y(), rtz = r.z() - t.z();
  const double rt2 = CGAL::square(rtx) + CGAL::square(rty) + CGAL::square(rtz);
  const double stx = s.x() - t.x(), sty = s.y() - t.y(), stz = s.z() - t.z();
  const double st2 = CGAL::square(stx) + CGAL::square(sty) + CGAL::square(stz);
  return CGAL::determinant(ptx, pty, ptz, pt2, rtx, rty, rtz, rt2, qtx, qty, qtz, qt2, stx, sty, stz, st2);
}

// CGAL::side_of_oriented_sphere(p, q, r, s, t).
inline int filtered_side_of_sphere(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s,
                                   const KPoint& t, double eps) {
  if (!(eps < std::numeric_limits<double>::infinity())) return side_of_sphere_out_of_line(p, q, r, s, t);
  const double det = side_of_sphere_det(p, q, r, s, t);
  if (det > eps) return 1;
  if (det < -eps) return -1;
  return side_of_sphere_semi_static(p, q, r, s, t, det);
}

// The box filter's verdict alone on CGAL::side_of_oriented_sphere(p, q, r,
// s, t): its sign when the determinant is beyond eps, 0 when the filter
// cannot decide (then filtered_side_of_sphere decides). The same
// determinant as filtered_side_of_sphere, so a nonzero verdict is that
// function's answer; computed without a branch on the sign, so that several
// can be in flight before one is acted on.
inline int box_side_of_sphere(const KPoint& p, const KPoint& q, const KPoint& r, const KPoint& s, const KPoint& t,
                              double eps) {
  const double det = side_of_sphere_det(p, q, r, s, t);
  return static_cast<int>(det > eps) - static_cast<int>(det < -eps);
}

inline bool lex_less(const KPoint* a, const KPoint* b) { return CGAL::compare_xyz(*a, *b) == CGAL::SMALLER; }

// The perturbation's decision for five points whose in-sphere determinant
// is exactly zero (see perturbed_insphere). Out of line: ties are rare.
[[gnu::noinline]] inline int perturbed_insphere_tie(const KPoint& p0, const KPoint& p1, const KPoint& p2,
                                                    const KPoint& p3, const KPoint& p) {
  const KPoint* pts[5] = {&p0, &p1, &p2, &p3, &p};
  std::sort(pts, pts + 5, lex_less);
  // Two iterations suffice (Devillers & Teillaud): the leading monomials.
  for (int i = 4; i > 2; --i) {
    if (pts[i] == &p) return -1;
    int o;
    if (pts[i] == &p3 && (o = orient(p0, p1, p2, p)) != 0) return o;
    if (pts[i] == &p2 && (o = orient(p0, p1, p, p3)) != 0) return o;
    if (pts[i] == &p1 && (o = orient(p0, p, p2, p3)) != 0) return o;
    if (pts[i] == &p0 && (o = orient(p, p1, p2, p3)) != 0) return o;
  }
  return -1;  // unreachable for a non-degenerate tetrahedron
}

// > 0: p inside the circumsphere of the positively oriented (p0,p1,p2,p3);
// < 0: outside. Never 0: ties are decided by the perturbation. eps: as for
// filtered_side_of_sphere (infinity: CGAL's predicate alone).
inline int perturbed_insphere(const KPoint& p0, const KPoint& p1, const KPoint& p2, const KPoint& p3,
                              const KPoint& p, double eps = std::numeric_limits<double>::infinity()) {
  const int s = filtered_side_of_sphere(p0, p1, p2, p3, p, eps);
  return s != 0 ? s : perturbed_insphere_tie(p0, p1, p2, p3, p);
}

inline int coplanar_orient(const KPoint& a, const KPoint& b, const KPoint& c) {
  return static_cast<int>(CGAL::coplanar_orientation(a, b, c));
}

// For p coplanar with the non-collinear (p0,p1,p2): > 0 p inside their
// circumcircle, < 0 outside; ties perturbed as above (CGAL's
// coplanar_side_of_bounded_circle with perturb = true).
inline int perturbed_incircle(const KPoint& p0, const KPoint& p1, const KPoint& p2, const KPoint& p) {
  int s = static_cast<int>(CGAL::coplanar_side_of_bounded_circle(p0, p1, p2, p));
  if (s != 0) return s;
  const KPoint* pts[4] = {&p0, &p1, &p2, &p};
  std::sort(pts, pts + 4, lex_less);
  int local = coplanar_orient(p0, p1, p2);
  for (int i = 3; i > 0; --i) {
    if (pts[i] == &p) return -1;
    int o;
    if (pts[i] == &p2 && (o = coplanar_orient(p0, p1, p)) != 0) return o * local;
    if (pts[i] == &p1 && (o = coplanar_orient(p0, p, p2)) != 0) return o * local;
    if (pts[i] == &p0 && (o = coplanar_orient(p, p1, p2)) != 0) return o * local;
  }
  return -local;
}

}  // namespace pdt::detail
