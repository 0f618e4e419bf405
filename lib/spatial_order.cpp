// SPDX-License-Identifier: MIT
#ifndef CGAL_LINKED_WITH_TBB
#define CGAL_LINKED_WITH_TBB 1  // CGAL's Parallel_tag sort; pdt links oneTBB
#endif
#include "spatial_order.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/parallel_sort.h>

#include <algorithm>
#include <numeric>
#include <utility>

#include "box_lattice.hpp"
#include "mix64.hpp"

namespace pdt::detail {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;

// Index -> CGAL point, read from the caller's points (no copy of the batch).
struct IndexToPoint {
  using key_type = std::uint32_t;
  using value_type = Kernel::Point_3;
  using reference = value_type;
  using category = boost::readable_property_map_tag;
  const Point3* points;
  friend value_type get(const IndexToPoint& m, std::uint32_t i) {
    const Point3& p = m.points[i];
    return {p.x, p.y, p.z};
  }
};

std::vector<std::uint32_t> cgal_order(std::span<const Point3> points, bool parallel) {
  std::vector<std::uint32_t> order(points.size());
  std::iota(order.begin(), order.end(), std::uint32_t{0});
  using Traits = CGAL::Spatial_sort_traits_adapter_3<Kernel, IndexToPoint>;
  Traits traits(IndexToPoint{points.data()});
  if (parallel)
    CGAL::spatial_sort<CGAL::Parallel_tag>(order.begin(), order.end(), traits);
  else
    CGAL::spatial_sort<CGAL::Sequential_tag>(order.begin(), order.end(), traits);
  return order;
}

constexpr int key_bits = 21;  // per axis: 63-bit keys

// The low 21 bits of v, spread to every third bit (bit i to bit 3i).
std::uint64_t spread3(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// The position of the lattice point x on the 3D Hilbert curve of order
// key_bits: Skilling's transform of the axes ("Programming the Hilbert curve",
// AIP Conf. Proc. 707, 2004), then the transposed bits interleaved.
std::uint64_t hilbert_key(std::uint32_t x[3]) {
  for (std::uint32_t q = 1u << (key_bits - 1); q > 1; q >>= 1) {
    const std::uint32_t p = q - 1;
    for (int i = 0; i < 3; ++i) {  // without branches: the bits are random
      const std::uint32_t set = 0u - ((x[i] & q) != 0);  // all ones if bit q of x[i] is set
      const std::uint32_t t = (x[0] ^ x[i]) & p & ~set;  // else: exchange the low bits of x[0] and x[i]
      x[0] ^= (p & set) | t;                              // if set: invert the low bits of x[0]
      x[i] ^= t;
    }
  }
  x[1] ^= x[0];
  x[2] ^= x[1];
  std::uint32_t t = 0;
  for (std::uint32_t q = 1u << (key_bits - 1); q > 1; q >>= 1) t ^= (q - 1) & (0u - ((x[2] & q) != 0));
  for (int i = 0; i < 3; ++i) x[i] ^= t;
  return spread3(x[0]) << 2 | spread3(x[1]) << 1 | spread3(x[2]);
}

struct Keyed {
  std::uint64_t key;
  std::uint32_t index;
  bool operator<(const Keyed& o) const { return key < o.key || (key == o.key && index < o.index); }
};

template <class Body>
void for_range(std::size_t n, bool parallel, const Body& body) {
  if (parallel)
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 14),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  else
    body(0, n);
}

}  // namespace

std::vector<std::uint32_t> spatial_order(std::span<const Point3> points, bool parallel) {
  // CGAL's order (spatial_sort: a BRIO whose rounds are Hilbert sorted), with
  // the Hilbert sort done on fixed-resolution keys: compute, then sort
  // integers, instead of CGAL's median splits, which reach each point
  // through the index at every level (0.3-0.45 s of a 4 s batch of 1M points).
  // The rounds, as CGAL's: a random shuffle, then the last 3/4 of the range
  // sorted and the first 1/4 again split the same way, down to 16 points.
  const std::size_t n = points.size();
  if (n < 64) return cgal_order(points, parallel);
  BoundingBox box;
  for (const Point3& p : points) box.add(p.x, p.y, p.z);
  // A flat axis maps to 0 there; a box reaching +-DBL_MAX, or a subnormal
  // one, scales without overflow (BoxLattice works on halves and pre-scales).
  const BoxLattice lattice(box.lo, box.hi, 1 << key_bits);
  // Keys in the points' order (reading them in the shuffled order would miss
  // the cache at each one), then the shuffle: Fisher-Yates from a fixed seed,
  // so the order (and the vertex ids it hands out) is the same on every run.
  std::vector<Keyed> items(n);
  for_range(n, parallel, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const double c[3] = {points[i].x, points[i].y, points[i].z};
      std::uint32_t x[3];
      for (int a = 0; a < 3; ++a) x[a] = static_cast<std::uint32_t>(lattice.index(a, c[a]));
      items[i] = {hilbert_key(x), static_cast<std::uint32_t>(i)};
    }
  });
  std::uint64_t state = 0x9e3779b97f4a7c15ull;
  for (std::size_t i = n - 1; i > 0; --i) {
    state = mix64(state + i);
    std::swap(items[i], items[state % (i + 1)]);
  }
  for (std::size_t end = n; end > 0;) {
    const std::size_t begin = end >= 16 ? end / 4 : 0;
    if (parallel)
      tbb::parallel_sort(items.begin() + static_cast<std::ptrdiff_t>(begin), items.begin() + static_cast<std::ptrdiff_t>(end));
    else
      std::sort(items.begin() + static_cast<std::ptrdiff_t>(begin), items.begin() + static_cast<std::ptrdiff_t>(end));
    end = begin;
  }
  // Keys too coarse for the points (a cluster far smaller than the box, or a
  // subnormal box): many
  // distinct points on one key leave them in shuffled order, so walks would
  // get long. Then CGAL's median splits, which adapt to any density.
  // (Copies of one point share their key harmlessly: not counted.)
  std::size_t shared_keys = 0;
  for (std::size_t i = 1; i < n; ++i)
    shared_keys += items[i].key == items[i - 1].key && !(points[items[i].index] == points[items[i - 1].index]);
  if (shared_keys > n / 64) return cgal_order(points, parallel);
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = items[i].index;
  return order;
}

}  // namespace pdt::detail
