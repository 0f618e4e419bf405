// SPDX-License-Identifier: MIT
#pragma once
// A static filter for the orientation and in-sphere tests among points known
// to lie in one box, in front of CGAL's own filtered predicates: the box and
// its epsilons; the tests that use them are predicates.hpp's filtered_*.
//
// CGAL's Epick predicates first try a semi-static filter: they evaluate the
// determinant in doubles, then bound its rounding error by a constant times
// the largest coordinate differences of the call's own points (maxx, maxy,
// maxz: three maxima over 3 or 4 differences, a sort, and range checks, per
// call). When every point of a test lies in a box [lo, hi], the differences
// are bounded by the box's extents instead, so that bound can be computed
// once per box: BoxFilter does so. A test then evaluates CGAL's determinant
// in CGAL's own order and compares it with the box's epsilon; only when
// |det| <= eps does it call CGAL's predicate (its semi-static filter, then
// interval arithmetic, then exact arithmetic). The sign returned is always
// the exact sign: the box's epsilon bounds the rounding error of every test
// among points of the box (below), so a determinant beyond it has the exact
// determinant's sign.
//
// Why the bound holds. For points a, b in [lo, hi] on an axis, |a - b| <=
// hi - lo, and rounding is monotone, so the computed |fl(a - b)| <= fl(hi -
// lo) =: B. CGAL's epsilon is a product of its constant and the maxima of
// the computed differences (Static_filters/Orientation_3.h, .../
// Side_of_oriented_sphere_3.h): c * maxx * maxy * maxz, times maxz^2 after
// sorting for the in-sphere test. The same product over Bx >= maxx, By >=
// maxy, Bz >= maxz and Bm = max(Bx, By, Bz) is no smaller (a product of
// non-negative factors, rounded monotonically at each step). CGAL's constant
// bounds the rounding error of the determinant when nothing underflows or
// overflows. Overflow: CGAL requires its largest maximum below 1e102
// (orientation) or 1e61 (in-sphere); Bm below the same limit implies it.
// Underflow: CGAL refuses to trust its epsilon when it would underflow; here
// the box's epsilon must be at least 1e-290 (a normal number, computed with
// its relative error, which CGAL's constant covers), else the filter is off.
// A product whose result underflows adds an absolute error of at most
// 2^-1075 (sums are exact when subnormal); that error is then multiplied by
// the rest of its term, whose size is below 6 * max(1, Bm) for the
// orientation's degree-3 terms and 72 * max(1, Bm)^4 for the in-sphere's
// degree-5 ones (entries up to Bm, squared norms up to 3 Bm^2, minors summed
// over their permutations), over fewer than 64 products. The slack added to
// epsilon, 4096 * 2^-1074 * max(1, Bm)^2 and 4096 * 2^-1074 * 72 * max(1,
// Bm)^4, covers that many times over, and the sum is rounded up by a
// relative 2^-40. (At most 1e-75 for a box of extent 1e61, where CGAL's own
// epsilon is above 1e290: the slack matters only for tiny boxes, and there
// it is still below 1e-315.)
//
// Invariant (checked in debug builds by BoxFilter::check): orient_eps and
// insphere_eps are the values compute() derives from lo and hi (+infinity:
// the filter is off, e.g. for an empty or degenerate box, whose tests all go
// to CGAL).
#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

#include "predicates.hpp"

namespace pdt::detail {

// The epsilons in force for one operation's tests: +infinity decides nothing.
struct FilterEps {
  double orient = std::numeric_limits<double>::infinity();
  double insphere = std::numeric_limits<double>::infinity();
};

class BoxFilter {
 public:
  BoxFilter() { clear(); }
  void clear() {
    constexpr double inf = std::numeric_limits<double>::infinity();
    lo_[0] = lo_[1] = lo_[2] = inf;
    hi_[0] = hi_[1] = hi_[2] = -inf;
    eps_ = FilterEps{};
  }
  bool contains(double x, double y, double z) const {
    return lo_[0] <= x && x <= hi_[0] && lo_[1] <= y && y <= hi_[1] && lo_[2] <= z && z <= hi_[2];
  }
  bool contains(const KPoint& p) const { return contains(p.x(), p.y(), p.z()); }
  // Grows the box to hold p and recomputes the epsilons.
  void extend(const KPoint& p) {
    const double c[3] = {p.x(), p.y(), p.z()};
    for (int i = 0; i < 3; ++i) {
      lo_[i] = std::min(lo_[i], c[i]);
      hi_[i] = std::max(hi_[i], c[i]);
    }
    eps_ = compute(lo_, hi_);
    assert(check());
  }
  // The epsilons for tests among points of the box, p one of them; off for
  // a p outside it.
  FilterEps eps_for(const KPoint& p) const { return contains(p) ? eps_ : FilterEps{}; }
  const FilterEps& eps() const { return eps_; }
  bool check() const {
    const FilterEps e = compute(lo_, hi_);
    return e.orient == eps_.orient && e.insphere == eps_.insphere;
  }

 private:
  static FilterEps compute(const double lo[3], const double hi[3]) {
    FilterEps e;
    double b[3];
    for (int i = 0; i < 3; ++i) {
      if (!(lo[i] <= hi[i])) return e;  // empty
      b[i] = hi[i] - lo[i];
    }
    const double bm = std::max({b[0], b[1], b[2]});
    if (!std::isfinite(bm)) return e;
    const double bm1 = std::max(1.0, bm);  // max(1, Bm) of the underflow slack
    constexpr double ulp_min = std::numeric_limits<double>::denorm_min();  // 2^-1074
    constexpr double round_up = 1.0 + 0x1p-40;
    if (bm < 1e102) {
      const double eps = 5.1107127829973299e-15 * b[0] * b[1] * b[2];  // CGAL's Orientation_3 constant
      if (eps >= 1e-290) e.orient = (eps + 4096 * ulp_min * (bm1 * bm1)) * round_up;
    }
    if (bm < 1e61) {
      // CGAL's Side_of_oriented_sphere_3 constant, and its order of factors.
      const double eps = 1.2466136531027298e-13 * b[0] * b[1] * b[2] * (bm * bm);
      if (eps >= 1e-290) e.insphere = (eps + 4096 * ulp_min * (72 * bm1 * bm1 * bm1 * bm1)) * round_up;
    }
    return e;
  }

  double lo_[3], hi_[3];
  FilterEps eps_;
};

}  // namespace pdt::detail
