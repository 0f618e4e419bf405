// SPDX-License-Identifier: MIT
// The batch insertion order (lib/spatial_order.cpp): a permutation, the same
// on every run and in both modes, and local (consecutive points close), for
// the sets that take its Hilbert keys (a span reaching +-DBL_MAX included) and
// for those that fall back to CGAL's median sort (a cluster far smaller than
// the box, a subnormal span).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <oneapi/tbb/task_arena.h>

#include "common/point_sets.hpp"
#include "spatial_order.hpp"

using pdt::Point3;
using pdt_test::generated_points;

namespace {

bool is_permutation_of_indices(const std::vector<std::uint32_t>& order, std::size_t n) {
  if (order.size() != n) return false;
  std::vector<std::uint32_t> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t i = 0; i < n; ++i)
    if (sorted[i] != i) return false;
  return true;
}

// The length of the path through pts[order[from..]], in units of `unit`
// (so that huge and subnormal coordinates neither overflow nor vanish).
double path_length(const std::vector<Point3>& pts, const std::vector<std::uint32_t>& order, std::size_t from,
                   double unit = 1) {
  double sum = 0;
  for (std::size_t k = from + 1; k < order.size(); ++k) {
    const Point3& a = pts[order[k - 1]];
    const Point3& b = pts[order[k]];
    const double d[3] = {a.x / unit - b.x / unit, a.y / unit - b.y / unit, a.z / unit - b.z / unit};
    sum += std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  }
  return sum;
}

std::vector<std::uint32_t> identity(std::size_t n) {
  std::vector<std::uint32_t> id(n);
  std::iota(id.begin(), id.end(), std::uint32_t{0});
  return id;
}

}  // namespace

TEST_CASE("spatial order: a permutation, the same every run and in both modes, and local", "[insert][order]") {
  std::vector<std::vector<Point3>> sets = {generated_points(pdt::Distribution::uniform, 20000, 3),
                                           generated_points(pdt::Distribution::normal, 20000, 4),
                                           generated_points(pdt::Distribution::line, 20000, 5)};
  // A plane (no extent along z) and copies of each point.
  std::vector<Point3> plane = generated_points(pdt::Distribution::uniform, 10000, 6);
  for (Point3& p : plane) p.z = 0.5;
  sets.push_back(plane);
  std::vector<Point3> copies = generated_points(pdt::Distribution::uniform, 5000, 7);
  copies.insert(copies.end(), copies.begin(), copies.end());
  sets.push_back(copies);
  // 2 and 3 threads: the rounds' radix sort in 2 and in 3 (uneven) parts.
  tbb::task_arena arenas[] = {tbb::task_arena(2), tbb::task_arena(3)};
  for (const auto& pts : sets) {
    INFO(pts.size() << " points");
    const std::vector<std::uint32_t> order = pdt::detail::spatial_order(pts, false);
    REQUIRE(is_permutation_of_indices(order, pts.size()));
    REQUIRE(pdt::detail::spatial_order(pts, false) == order);
    for (tbb::task_arena& arena : arenas) {
      std::vector<std::uint32_t> parallel;
      arena.execute([&] { parallel = pdt::detail::spatial_order(pts, true); });
      REQUIRE(parallel == order);  // keys and (key, index) ties decide: threads do not
    }
    // Its last round, 3/4 of the points along one curve: a fraction of the
    // input order's path (random points: about 1/10 here; a broken key
    // would leave it near 1).
    const std::size_t last_round = pts.size() / 4;
    REQUIRE(path_length(pts, order, last_round) < 0.25 * path_length(pts, identity(pts.size()), last_round));
  }
}

TEST_CASE("spatial order: a cluster far smaller than the box, huge and subnormal spans", "[insert][order]") {
  // 5000 points in a cube of side 1e-9 (one key for all of them at 2^-21 of
  // the box: the order falls back to CGAL's median sort), 5000 spread over
  // [0, 1000]^3.
  std::vector<Point3> cluster = generated_points(pdt::Distribution::uniform, 5000, 8);
  for (Point3& p : cluster) p = {0.5 + 1e-9 * p.x, 0.5 + 1e-9 * p.y, 0.5 + 1e-9 * p.z};
  for (Point3 p : generated_points(pdt::Distribution::uniform, 5000, 11))
    cluster.push_back({1000 * p.x, 1000 * p.y, 1000 * p.z});
  // A span a double cannot hold (hi - lo overflows; the keys scale halves),
  // and a subnormal one (no key tells its points apart: CGAL's sort).
  std::vector<Point3> huge = generated_points(pdt::Distribution::uniform, 1000, 9);
  for (Point3& p : huge) p = {(2 * p.x - 1) * 1.5e308, (2 * p.y - 1) * 1.5e308, (2 * p.z - 1) * 1.5e308};
  std::vector<Point3> tiny = generated_points(pdt::Distribution::uniform, 1000, 10);
  for (Point3& p : tiny) p = {p.x * 1e-310, p.y * 1e-310, p.z * 1e-310};
  const std::pair<const std::vector<Point3>*, double> cases[] = {{&cluster, 1}, {&huge, 1e308}, {&tiny, 1e-310}};
  for (const auto& [set, unit] : cases) {
    const std::vector<Point3>& pts = *set;
    INFO(pts.size() << " points, unit " << unit);
    const std::vector<std::uint32_t> order = pdt::detail::spatial_order(pts, false);
    REQUIRE(is_permutation_of_indices(order, pts.size()));
    REQUIRE(pdt::detail::spatial_order(pts, false) == order);
    const std::size_t last_round = pts.size() / 4;
    REQUIRE(path_length(pts, order, last_round, unit) <
            0.25 * path_length(pts, identity(pts.size()), last_round, unit));
  }
}

TEST_CASE("spatial order: brio_round numbers the rounds the order sorts", "[insert][order]") {
  // Rounds [n/4, n), [n/16, n/4), ... down to an end below 16: numbered 0, 1, ...
  const std::size_t n = 1000;
  CHECK(pdt::detail::brio_round(999, n) == 0);
  CHECK(pdt::detail::brio_round(250, n) == 0);
  CHECK(pdt::detail::brio_round(249, n) == 1);
  CHECK(pdt::detail::brio_round(62, n) == 1);
  CHECK(pdt::detail::brio_round(61, n) == 2);
  CHECK(pdt::detail::brio_round(15, n) == 2);
  CHECK(pdt::detail::brio_round(14, n) == 3);  // [0, 15): the first round, its end below 16 after it
  CHECK(pdt::detail::brio_round(0, n) == 3);
  CHECK(pdt::detail::brio_round(5, 10) == 0);  // fewer than 16: one round
  // From one position to the next the round stays or steps back by one.
  for (std::size_t k = 1; k < n; ++k) {
    const unsigned a = pdt::detail::brio_round(k - 1, n), b = pdt::detail::brio_round(k, n);
    CHECK((a == b || a == b + 1));
  }
}
