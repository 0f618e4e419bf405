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
#include <limits>

#include "box_filter.hpp"
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
// < 0: outside. Never 0: ties are decided by the perturbation. eps: a
// BoxFilter's in-sphere epsilon for a box holding the five points (infinity:
// none), which decides the clear cases before CGAL's predicate.
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
