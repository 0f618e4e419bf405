// SPDX-License-Identifier: MIT
#include "jump_grid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace pdt::detail {

VertexId JumpGrid::lookup(const KPoint& p) const {
  std::size_t s = slot_of(p);
  VertexId v = get(s);
  if (v != no_vertex) return v;
  const int res = lattice.res;
  const int x = static_cast<int>(s % res), y = static_cast<int>((s / res) % res), z = static_cast<int>(s / res / res);
  for (int r = 1; r <= 2; ++r)
    for (int dz = -r; dz <= r; ++dz)
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
          if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
          int a = x + dx, b = y + dy, c = z + dz;
          if (a < 0 || b < 0 || c < 0 || a >= res || b >= res || c >= res) continue;
          v = get((static_cast<std::size_t>(c) * res + b) * res + a);
          if (v != no_vertex) return v;
        }
  return no_vertex;
}

JumpGrid JumpGrid::build(const StableArray<VertexRec>& verts, std::size_t slots) {
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  const std::size_t bound = verts.size();
  std::size_t n = 0;
  for (VertexId v = 1; v < bound; ++v) {
    if (verts[v].multiplicity == 0) continue;
    ++n;
    const KPoint& p = verts[v].p;
    const double c[3] = {p.x(), p.y(), p.z()};
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
  }
  // About 2 vertices per slot right after a build, so few slots are empty.
  const std::size_t want = std::min<std::size_t>(slots ? slots : std::max<std::size_t>(1, n / 2), std::size_t{1} << 30);
  JumpGrid g;
  g.lattice = BoxLattice(lo, hi, std::max(1, static_cast<int>(std::cbrt(static_cast<double>(want)))));
  const std::size_t res = static_cast<std::size_t>(g.lattice.res);
  g.slot_count = res * res * res;
  g.slots = std::make_unique<std::atomic<VertexId>[]>(g.slot_count);
  for (std::size_t s = 0; s < g.slot_count; ++s) g.set(s, no_vertex);
  for (VertexId v = 1; v < bound; ++v)
    if (verts[v].multiplicity > 0) g.set(g.slot_of(verts[v].p), v);
  g.built_for = n;
  return g;
}

}  // namespace pdt::detail
