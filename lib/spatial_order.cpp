// SPDX-License-Identifier: MIT
#ifndef CGAL_LINKED_WITH_TBB
#define CGAL_LINKED_WITH_TBB 1  // CGAL's Parallel_tag sort; pdt links oneTBB
#endif
#include "spatial_order.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>

#include <numeric>

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

}  // namespace

std::vector<std::uint32_t> spatial_order(std::span<const Point3> points, bool parallel) {
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

}  // namespace pdt::detail
