// SPDX-License-Identifier: MIT
#include "refine/domain.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <unordered_map>

#include "pdt/error.hpp"

namespace pdt_refine {

namespace {

using pdt::Point3;

double sphere(const Point3& p) { return std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) - 1; }

double torus(const Point3& p) {
  const double r = std::sqrt(p.x * p.x + p.y * p.y) - 1;
  return std::sqrt(r * r + p.z * p.z) - 0.4;
}

// The cube [-1, 1]^3 the gyroid is cut by: max |coordinate| - 1, which
// changes by at most |p - q| between p and q.
double gyroid_cube(const Point3& p) { return std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)}) - 1; }

// The gyroid's level function at frequency pi, divided by its gradient's
// length so that near the surface it is about a distance; the slab is
// |g| < 0.6 (in those units: about 0.12), cut by the cube [-1, 1]^3.
double gyroid(const Point3& p) {
  const double k = M_PI;
  const double x = k * p.x, y = k * p.y, z = k * p.z;
  const double g = std::sin(x) * std::cos(y) + std::sin(y) * std::cos(z) + std::sin(z) * std::cos(x);
  const double gx = k * (std::cos(x) * std::cos(y) - std::sin(z) * std::sin(x));
  const double gy = k * (-std::sin(x) * std::sin(y) + std::cos(y) * std::cos(z));
  const double gz = k * (-std::sin(y) * std::sin(z) + std::cos(z) * std::cos(x));
  const double grad = std::max(std::sqrt(gx * gx + gy * gy + gz * gz), 0.5);
  const double slab = (std::fabs(g) - 0.6) / grad;
  return std::max(slab, gyroid_cube(p));
}

// The gyroid's f has one sign on the ball (c, reach) when the cube's or the
// raw level function's bounds say so: |g| changes by at most
// |grad g| <= 2 sqrt(3) pi per unit (each partial derivative is pi times a
// sum of two products of sines and cosines), the cube's term by at most 1,
// and f < 0 exactly where |g| < 0.6 and the cube's term < 0 (its division by
// the gradient's length keeps the sign). A 1e-9 margin covers rounding.
bool gyroid_uncrossed(const Point3& c, double reach) {
  const double k = M_PI, lip = 2 * std::sqrt(3.0) * k, margin = 1e-9;
  const double x = k * c.x, y = k * c.y, z = k * c.z;
  const double g = std::fabs(std::sin(x) * std::cos(y) + std::sin(y) * std::cos(z) + std::sin(z) * std::cos(x));
  const double cube = gyroid_cube(c);
  if (cube > reach + margin || g - 0.6 > lip * reach + margin) return true;  // outside on the whole ball
  return cube < -reach - margin && 0.6 - g > lip * reach + margin;            // inside on the whole ball
}

Point3 gradient(double (*f)(const Point3&), const Point3& p, double h) {
  return {(f({p.x + h, p.y, p.z}) - f({p.x - h, p.y, p.z})) / (2 * h),
          (f({p.x, p.y + h, p.z}) - f({p.x, p.y - h, p.z})) / (2 * h),
          (f({p.x, p.y, p.z + h}) - f({p.x, p.y, p.z - h})) / (2 * h)};
}

}  // namespace

const char* domain_names() { return "sphere, torus, gyroid"; }

Domain domain_by_name(const std::string& name) {
  // sphere and torus: distance functions (Lipschitz 1); the gyroid's
  // normalised level function has no simple bound.
  if (name == "sphere") return {"sphere", {{-1.5, -1.5, -1.5}, {1.5, 1.5, 1.5}}, sphere, 1, 1};
  if (name == "torus") return {"torus", {{-1.9, -1.9, -0.9}, {1.9, 1.9, 0.9}}, torus, 1, 1};
  if (name == "gyroid") return {"gyroid", {{-1.5, -1.5, -1.5}, {1.5, 1.5, 1.5}}, gyroid, 1, 0, gyroid_cube, gyroid_uncrossed};
  throw pdt::Error(pdt::ErrorCode::invalid_argument,
                   "unknown domain '" + name + "'; expected one of: " + domain_names());
}

std::vector<Point3> surface_samples(const Domain& d, double spacing, std::uint64_t seed, std::size_t max_candidates,
                                    bool* too_many) {
  if (too_many) *too_many = false;
  // Candidates: the centres of grid cells (of size spacing) whose corners
  // disagree on the side of the surface, projected onto it; kept with their
  // cell's number, so that the order below is the grid's whatever the scan's.
  const double h = spacing;
  const std::int64_t nx = static_cast<std::int64_t>(std::ceil((d.box.hi.x - d.box.lo.x) / h));
  const std::int64_t ny = static_cast<std::int64_t>(std::ceil((d.box.hi.y - d.box.lo.y) / h));
  const std::int64_t nz = static_cast<std::int64_t>(std::ceil((d.box.hi.z - d.box.lo.z) / h));
  auto at = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return Point3{d.box.lo.x + static_cast<double>(i) * h, d.box.lo.y + static_cast<double>(j) * h,
                  d.box.lo.z + static_cast<double>(k) * h};
  };
  std::vector<std::pair<std::int64_t, Point3>> found;
  auto visit_cell = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    bool in = false, out = false;
    for (int c = 0; c < 8; ++c) {
      const double v = d.f(at(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)));
      (v < 0 ? in : out) = true;
    }
    if (!(in && out)) return;
    Point3 p = at(i, j, k);
    p = {p.x + h / 2, p.y + h / 2, p.z + h / 2};
    for (int step = 0; step < 20; ++step) {  // Newton on f along its gradient
      const double v = d.f(p);
      if (std::fabs(v) < 1e-12) break;
      const Point3 g = gradient(d.f, p, 1e-7);
      const double g2 = g.x * g.x + g.y * g.y + g.z * g.z;
      if (!(g2 > 0)) break;
      p = {p.x - v * g.x / g2, p.y - v * g.y / g2, p.z - v * g.z / g2};
    }
    if (std::fabs(d.f(p)) < 1e-6 && d.box.contains(p)) found.push_back({(k * ny + j) * nx + i, p});
  };
  // Blocks of B^3 cells: with a Lipschitz bound L, a block whose centre has
  // |f| > L * (its half-diagonal) holds no corner of the other sign, so none
  // of its cells is crossed: skipped (a 1e-9 relative margin for rounding).
  constexpr std::int64_t B = 8;
  for (std::int64_t k0 = 0; k0 < nz; k0 += B)
    for (std::int64_t j0 = 0; j0 < ny; j0 += B)
      for (std::int64_t i0 = 0; i0 < nx; i0 += B) {
        const std::int64_t i1 = std::min(nx, i0 + B), j1 = std::min(ny, j0 + B), k1 = std::min(nz, k0 + B);
        if (d.lipschitz > 0 || d.outside_bound || d.uncrossed) {
          const Point3 lo = at(i0, j0, k0), hi = at(i1, j1, k1);
          const Point3 c{(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
          const double reach =
              std::sqrt((hi.x - lo.x) * (hi.x - lo.x) + (hi.y - lo.y) * (hi.y - lo.y) + (hi.z - lo.z) * (hi.z - lo.z)) / 2 *
                  (1 + 1e-9) +
              1e-12;
          if (d.lipschitz > 0 && std::fabs(d.f(c)) > d.lipschitz * reach) continue;
          if (d.outside_bound && d.outside_bound(c) > reach) continue;  // f > 0 on the whole block
          if (d.uncrossed && d.uncrossed(c, reach)) continue;           // one sign on the whole block
        }
        for (std::int64_t k = k0; k < k1; ++k)
          for (std::int64_t j = j0; j < j1; ++j)
            for (std::int64_t i = i0; i < i1; ++i) visit_cell(i, j, k);
        if (found.size() > max_candidates) {
          if (too_many) *too_many = true;
          return {};
        }
      }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Point3> candidates;
  candidates.reserve(found.size());
  for (const auto& c : found) candidates.push_back(c.second);
  found = {};
  // Thin them, in a seeded order, so that no two are closer than spacing / 2.
  std::mt19937_64 rng(seed);
  std::shuffle(candidates.begin(), candidates.end(), rng);
  const double r = spacing / 2;
  auto key = [&](const Point3& p) {
    const auto c = [&](double v, double lo) { return static_cast<std::int64_t>(std::floor((v - lo) / r)); };
    return std::array<std::int64_t, 3>{c(p.x, d.box.lo.x), c(p.y, d.box.lo.y), c(p.z, d.box.lo.z)};
  };
  struct Hash {
    std::size_t operator()(const std::array<std::int64_t, 3>& k) const {
      return static_cast<std::size_t>(k[0] * 73856093 ^ k[1] * 19349663 ^ k[2] * 83492791);
    }
  };
  std::unordered_map<std::array<std::int64_t, 3>, std::vector<Point3>, Hash> near;
  std::vector<Point3> kept;
  for (const Point3& p : candidates) {
    const auto k = key(p);
    bool clear = true;
    for (int dz = -1; dz <= 1 && clear; ++dz)
      for (int dy = -1; dy <= 1 && clear; ++dy)
        for (int dx = -1; dx <= 1 && clear; ++dx) {
          auto it = near.find({k[0] + dx, k[1] + dy, k[2] + dz});
          if (it == near.end()) continue;
          for (const Point3& q : it->second)
            if ((p.x - q.x) * (p.x - q.x) + (p.y - q.y) * (p.y - q.y) + (p.z - q.z) * (p.z - q.z) < r * r) clear = false;
        }
    if (!clear) continue;
    near[k].push_back(p);
    kept.push_back(p);
  }
  return kept;
}

}  // namespace pdt_refine
