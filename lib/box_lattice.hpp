// SPDX-License-Identifier: MIT
#pragma once
// A box cut into res^3 equal cells: which cell holds a coordinate. The one
// place pdt scales coordinates to a box (the jump grid's slots, the engine's
// blocks, the Morton order of a first build, the Hilbert keys of a batch's
// order).
//
// Everything is computed on halves (0.5 * c - 0.5 * lo), so no difference
// overflows even for boxes reaching +-DBL_MAX; an extent so small that
// res / extent overflows (subnormal boxes) is first scaled up by a power of
// two (exact), so such a box is cut as finely as any. A coordinate outside
// the box, or NaN, lands in the nearest end cell; a flat axis (lo == hi) maps
// everything to cell 0.
#include <cmath>

namespace pdt::detail {

// The smallest box holding the coordinates added to it; empty (lo > hi) until
// the first. The one bounding-box loop of the jump grid and the batch order.
struct BoundingBox {
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL};
  double hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  void add(double x, double y, double z) {
    const double c[3] = {x, y, z};
    for (int a = 0; a < 3; ++a) lo[a] = c[a] < lo[a] ? c[a] : lo[a], hi[a] = c[a] > hi[a] ? c[a] : hi[a];
  }
};

struct BoxLattice {
  double half_lo[3] = {0, 0, 0};
  double pre[3] = {1, 1, 1};    // 1, or 2^1000 for an extent too tiny to divide res by
  double scale[3] = {0, 0, 0};  // res / (half extent * pre); 0 for a flat axis
  int res = 1;

  BoxLattice() = default;
  BoxLattice(const double lo[3], const double hi[3], int cells_per_axis) : res(cells_per_axis < 1 ? 1 : cells_per_axis) {
    for (int a = 0; a < 3; ++a) {
      half_lo[a] = 0.5 * lo[a];
      const double half_extent = 0.5 * hi[a] - 0.5 * lo[a];
      if (!(half_extent > 0) || !std::isfinite(half_extent)) continue;  // flat (or NaN): cell 0
      // 2^1000 brings any positive extent (>= 2^-1075) to >= 2^-75: res over it is finite.
      if (!std::isfinite(res / half_extent)) pre[a] = 0x1p1000;
      scale[a] = res / (half_extent * pre[a]);
    }
  }

  // The cell along axis a that holds coordinate c, in [0, res).
  int index(int a, double c) const {
    const double t = (0.5 * c - half_lo[a]) * pre[a] * scale[a];
    return !(t > 0) ? 0 : t >= res - 1 ? res - 1 : static_cast<int>(t);
  }
  // Where c lies along axis a in units of cells, clamped to [0, res]: its
  // integer part is index(a, c) except at the far end (res, in cell res - 1).
  double position(int a, double c) const {
    const double t = (0.5 * c - half_lo[a]) * pre[a] * scale[a];
    return !(t > 0) ? 0.0 : t < res ? t : static_cast<double>(res);
  }
};

}  // namespace pdt::detail
