// SPDX-License-Identifier: MIT
// Synthetic operation streams (see include/pdt/generate.hpp).
//
// Reproducibility: the same options give the same stream, bit for bit, on every
// platform. Hence no <random> distributions (their algorithms are unspecified)
// and no libm transcendental functions (log/sin/cos results differ between C
// libraries): only xoshiro256** integers, IEEE-exact operations (+ - * / sqrt,
// frexp) and a fixed-order series for the logarithm the normal sampler needs.
// Points and the removal schedule use two independent generator streams, so the
// points of a seed do not depend on the removal options.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "pdt/error.hpp"
#include "pdt/generate.hpp"

// Contracting a*b+c into a fused multiply-add would change results on machines
// that have FMA. GCC in ISO mode (-std=c++20, as pdt builds) does not contract;
// clang does unless told.
#if defined(__clang__)
#pragma clang fp contract(off)
#endif

namespace pdt {

namespace {

std::uint64_t splitmix64(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// xoshiro256** (Blackman & Vigna), seeded through splitmix64 as its authors advise.
class Rng {
 public:
  Rng(std::uint64_t seed, std::uint64_t stream) {
    std::uint64_t sm = seed ^ (stream * 0xD1B54A32D192ED03ull);
    for (auto& w : s_) w = splitmix64(sm);
  }
  std::uint64_t next() {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }
  // Uniform in [0, 1) on the grid of multiples of 2^-53.
  double uniform01() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  // Uniform in [0, n), n > 0, without modulo bias.
  std::uint64_t below(std::uint64_t n) {
    const std::uint64_t threshold = (0 - n) % n;  // 2^64 mod n
    while (true) {
      std::uint64_t r = next();
      if (r >= threshold) return r % n;
    }
  }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t s_[4];
};

// Natural logarithm from IEEE-exact operations only, so it gives the same bits
// everywhere (libm's log need not). x > 0 finite. Relative error ~1e-16, far
// below what a point sampler can notice.
double portable_log(double x) {
  int e = 0;
  double m = std::frexp(x, &e);  // x = m * 2^e, m in [0.5, 1): exact
  if (m < 0.70710678118654752440) {
    m *= 2;  // exact
    --e;
  }
  // m in [sqrt(1/2), sqrt(2)): ln m = 2 atanh(s), s = (m-1)/(m+1), |s| < 0.172.
  const double s = (m - 1) / (m + 1);
  const double s2 = s * s;
  double term = s, sum = s;
  for (int k = 3; k <= 29; k += 2) {  // s^29/29 < 1e-24: the series has converged
    term *= s2;
    sum += term / k;
  }
  constexpr double ln2_hi = 0.693147180369123816490;  // ln 2 split so e*ln2_hi is exact
  constexpr double ln2_lo = 1.90821492927058770002e-10;
  return (e * ln2_hi + 2 * sum) + e * ln2_lo;
}

// Standard normal deviates by the Box-Muller transform in Marsaglia's polar
// form (needs a logarithm and a square root, no sine or cosine).
class NormalSampler {
 public:
  explicit NormalSampler(Rng& rng) : rng_(rng) {}
  double next() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    double u, v, s;
    do {
      u = 2 * rng_.uniform01() - 1;
      v = 2 * rng_.uniform01() - 1;
      s = u * u + v * v;
    } while (s >= 1 || s == 0);
    const double f = std::sqrt(-2 * portable_log(s) / s);
    spare_ = v * f;
    have_spare_ = true;
    return u * f;
  }

 private:
  Rng& rng_;
  double spare_ = 0;
  bool have_spare_ = false;
};

const Box kUnitBox{{0, 0, 0}, {1, 1, 1}};

void gen_uniform(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  for (std::uint64_t i = 0; i < n; ++i) {
    double x = rng.uniform01(), y = rng.uniform01(), z = rng.uniform01();
    pts.push_back({x, y, z});
  }
}

void gen_normal(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  NormalSampler g(rng);
  // Coordinates are independent, so rejecting each outside [0, 1] separately
  // samples the same distribution as rejecting whole points, with fewer draws.
  auto coord = [&] {
    while (true) {
      double c = 0.5 + 0.15 * g.next();
      if (c >= 0 && c <= 1) return c;
    }
  };
  for (std::uint64_t i = 0; i < n; ++i) {
    double x = coord(), y = coord(), z = coord();
    pts.push_back({x, y, z});
  }
}

void gen_line(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  for (std::uint64_t i = 0; i < n; ++i) {
    const double x = rng.uniform01();
    const double u = rng.uniform01();
    const double r = 0.5 * u * u * u;  // distance from the line y = z = 0.5
    // A uniform direction in the (y, z) plane: a uniform point of the unit
    // disk, normalised (no sin/cos, see the file comment).
    double a, b, q;
    do {
      a = 2 * rng.uniform01() - 1;
      b = 2 * rng.uniform01() - 1;
      q = a * a + b * b;
    } while (q > 1 || q == 0);
    const double len = std::sqrt(q);
    // Rounding may push a coordinate a hair outside [0, 1]: clamp so the unit box holds every point.
    const double y = std::clamp(0.5 + r * (a / len), 0.0, 1.0);
    const double z = std::clamp(0.5 + r * (b / len), 0.0, 1.0);
    pts.push_back({x, y, z});
  }
}

void gen_corner(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  gen_uniform(rng, n, pts);
  for (Point3& p : pts) p = {0.45 * p.x, 0.45 * p.y, 0.45 * p.z};
}

void gen_kuzmin(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  constexpr double a = 0.05;
  while (pts.size() < n) {
    const double u = rng.uniform01();
    if (u >= 1) continue;
    const double w = 1 / (1 - u);
    const double r = a * std::sqrt(w * w - 1);
    double dx, dy, dz, q;  // a uniform direction: a point of the unit ball, normalised
    do {
      dx = 2 * rng.uniform01() - 1;
      dy = 2 * rng.uniform01() - 1;
      dz = 2 * rng.uniform01() - 1;
      q = dx * dx + dy * dy + dz * dz;
    } while (q > 1 || q < 1e-12);
    const double f = r / std::sqrt(q);
    const Point3 p{0.5 + f * dx, 0.5 + f * dy, 0.5 + f * dz};
    if (p.x >= 0 && p.x <= 1 && p.y >= 0 && p.y <= 1 && p.z >= 0 && p.z <= 1) pts.push_back(p);
  }
}

void gen_clusters(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  gen_uniform(rng, n, pts);
  for (std::uint64_t i = 1; i < n; i += 2) {
    const double c = (i / 2) % 2 ? 0.7 : 0.2;
    Point3& p = pts[static_cast<std::size_t>(i)];
    p = {c + 1e-4 * p.x, c + 1e-4 * p.y, c + 1e-4 * p.z};
  }
}

// Uniform points in increasing order of one coordinate (ties keep their draw order).
void gen_front(Rng& rng, std::uint64_t n, int axis, std::vector<Point3>& pts) {
  gen_uniform(rng, n, pts);
  auto key = [axis](const Point3& p) { return axis == 0 ? p.x : axis == 1 ? p.y : p.z; };
  std::stable_sort(pts.begin(), pts.end(), [&](const Point3& a, const Point3& b) { return key(a) < key(b); });
}

// Shuffles the first `take` positions of v (partial Fisher-Yates): they become
// a uniformly random ordered sample of v's elements.
template <class T>
void partial_shuffle(Rng& rng, std::vector<T>& v, std::size_t take) {
  for (std::size_t i = 0; i < take && i + 1 < v.size(); ++i) {
    std::size_t j = i + static_cast<std::size_t>(rng.below(v.size() - i));
    std::swap(v[i], v[j]);
  }
}

// k x k x k lattice {0..k-1}^3 with k the smallest integer such that k^3 >= n;
// the first n of a seeded shuffle.
Box gen_grid(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  std::uint64_t k = 1;
  while (k * k * k < n) ++k;
  const std::uint64_t total = k * k * k;
  // total < 2^32: generate() caps n below 1625^3, so k <= 1625.
  std::vector<std::uint32_t> idx(total);
  for (std::uint64_t i = 0; i < total; ++i) idx[i] = static_cast<std::uint32_t>(i);
  partial_shuffle(rng, idx, n);
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::uint64_t c = idx[i];
    pts.push_back({static_cast<double>(c % k), static_cast<double>((c / k) % k), static_cast<double>(c / (k * k))});
  }
  const double hi = static_cast<double>(k - 1);
  return Box{{0, 0, 0}, {hi, hi, hi}};
}

// r3(R^2): the number of integer points on the sphere x^2+y^2+z^2 = R^2.
// Classical formula: r3(n^2) = 6 prod over odd primes p^a || n of
// (sigma(p^a) - (-1/p) sigma(p^(a-1))), with (-1/p) = +1 for p = 1 mod 4 and
// -1 for p = 3 mod 4; powers of 2 contribute 1.
std::uint64_t sphere_count(std::uint64_t r) {
  while (r % 2 == 0) r /= 2;
  std::uint64_t count = 6;
  for (std::uint64_t p = 3; p * p <= r; p += 2) {
    if (r % p != 0) continue;
    std::uint64_t pa = 1, sigma_prev = 0, sigma = 1;  // sigma(p^a), sigma(p^(a-1))
    while (r % p == 0) {
      r /= p;
      pa *= p;
      sigma_prev = sigma;
      sigma += pa;
    }
    count *= (p % 4 == 1) ? sigma - sigma_prev : sigma + sigma_prev;
  }
  if (r > 1) count *= (r % 4 == 1) ? r : r + 2;  // a = 1: (r + 1) -/+ 1
  return count;
}

std::int64_t isqrt(std::int64_t m) {
  auto s = static_cast<std::int64_t>(std::sqrt(static_cast<double>(m)));
  while (s * s > m) --s;
  while ((s + 1) * (s + 1) <= m) ++s;
  return s;
}

// All integer points on x^2+y^2+z^2 = R^2 with R the smallest radius having at
// least n of them; the first n of a seeded shuffle.
Box gen_sphere(Rng& rng, std::uint64_t n, std::vector<Point3>& pts) {
  std::uint64_t R = 1;
  while (sphere_count(R) < n) ++R;
  const auto r = static_cast<std::int64_t>(R);
  const std::int64_t r2 = r * r;
  struct IP {
    std::int32_t c[3];
  };
  std::vector<IP> all;
  all.reserve(static_cast<std::size_t>(sphere_count(R)));
  // Enumerate 0 <= x <= y <= z, then expand by permutations and signs.
  for (std::int64_t x = 0; 3 * x * x <= r2; ++x) {
    for (std::int64_t y = x; x * x + 2 * y * y <= r2; ++y) {
      const std::int64_t m = r2 - x * x - y * y;
      const std::int64_t z = isqrt(m);
      if (z * z != m) continue;  // z >= y holds since m >= y^2
      const std::int32_t base[3] = {static_cast<std::int32_t>(x), static_cast<std::int32_t>(y),
                                    static_cast<std::int32_t>(z)};
      static constexpr int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
      IP distinct[6];
      int nd = 0;
      for (const auto& p : perms) {
        IP q{{base[p[0]], base[p[1]], base[p[2]]}};
        bool seen = false;
        for (int i = 0; i < nd; ++i)
          seen = seen || (distinct[i].c[0] == q.c[0] && distinct[i].c[1] == q.c[1] && distinct[i].c[2] == q.c[2]);
        if (!seen) distinct[nd++] = q;
      }
      for (int i = 0; i < nd; ++i) {
        for (int signs = 0; signs < 8; ++signs) {
          IP q = distinct[i];
          bool redundant = false;
          for (int a = 0; a < 3; ++a) {
            if (signs & (1 << a)) {
              if (q.c[a] == 0) redundant = true;  // -0 == 0: counted by the sign pattern without this bit
              q.c[a] = -q.c[a];
            }
          }
          if (!redundant) all.push_back(q);
        }
      }
    }
  }
  // The enumeration and the formula are independent; disagreement is a bug here.
  if (all.size() != sphere_count(R))
    throw std::logic_error("pdt::generate: sphere enumeration disagrees with r3(R^2) for R = " + std::to_string(R));
  partial_shuffle(rng, all, n);
  for (std::uint64_t i = 0; i < n; ++i)
    pts.push_back({static_cast<double>(all[i].c[0]), static_cast<double>(all[i].c[1]), static_cast<double>(all[i].c[2])});
  const double h = static_cast<double>(R);
  return Box{{-h, -h, -h}, {h, h, h}};
}

// How far after insertion k its interleaved removal may come (in insertions).
constexpr std::uint64_t kInterleaveWindow = 1024;

}  // namespace

OpStream generate(const GenerateOptions& o) {
  if (!(o.remove_fraction >= 0 && o.remove_fraction <= 1))
    throw Error(ErrorCode::invalid_argument,
                "generate: remove_fraction is " + std::to_string(o.remove_fraction) + "; expected a number in [0, 1]");
  constexpr std::uint64_t kMaxPoints = GenerateOptions::max_points;  // below 1625^3
  static_assert(kMaxPoints <= std::uint64_t{1625} * 1625 * 1625);
  if (o.points > kMaxPoints)
    throw Error(ErrorCode::invalid_argument,
                "generate: " + std::to_string(o.points) + " points requested; at most " + std::to_string(kMaxPoints));
  if (o.removal_order != RemovalOrder::after && o.removal_order != RemovalOrder::interleaved)
    throw Error(ErrorCode::invalid_argument,
                "generate: unknown removal order " + std::to_string(static_cast<int>(o.removal_order)) +
                    "; expected RemovalOrder::after or RemovalOrder::interleaved");
  const std::uint64_t n = o.points;
  Rng point_rng(o.seed, 0);
  std::vector<Point3> pts;
  pts.reserve(static_cast<std::size_t>(n));
  Box box = kUnitBox;
  switch (o.dist) {
    case Distribution::uniform: gen_uniform(point_rng, n, pts); break;
    case Distribution::normal: gen_normal(point_rng, n, pts); break;
    case Distribution::line: gen_line(point_rng, n, pts); break;
    case Distribution::grid: box = gen_grid(point_rng, n, pts); break;
    case Distribution::sphere: box = gen_sphere(point_rng, n, pts); break;
    case Distribution::corner: gen_corner(point_rng, n, pts); break;
    case Distribution::kuzmin: gen_kuzmin(point_rng, n, pts); break;
    case Distribution::front_x: gen_front(point_rng, n, 0, pts); break;
    case Distribution::front_y: gen_front(point_rng, n, 1, pts); break;
    case Distribution::front_z: gen_front(point_rng, n, 2, pts); break;
    case Distribution::clusters: gen_clusters(point_rng, n, pts); break;
    default: throw Error(ErrorCode::invalid_argument, "generate: unknown distribution");
  }

  // The first m insertions get undone: floor(F * n) for F as written in
  // decimal. The double nearest 0.29 is a little below it, and 0.29 * 100
  // comes out as 28.999999999999996; a product within a few rounding errors
  // below an integer is that integer (parsing F and the product are each
  // within half an ulp).
  const double wanted = o.remove_fraction * static_cast<double>(n);
  double whole = std::floor(wanted);
  if (whole + 1 - wanted <= 4 * std::numeric_limits<double>::epsilon() * wanted) whole += 1;
  const std::uint64_t m = std::min(static_cast<std::uint64_t>(whole), n);

  OpStream st;
  st.box = box;
  st.ops.reserve(static_cast<std::size_t>(n + m));
  auto insert = [&](std::uint64_t k) {
    Operation op;
    op.kind = Operation::Kind::insert;
    op.point = pts[k];
    st.ops.push_back(op);
  };
  auto remove = [&](std::uint64_t k) {
    Operation op;
    op.kind = Operation::Kind::remove;
    op.target = k;
    st.ops.push_back(op);
  };
  if (o.removal_order == RemovalOrder::after || m == 0) {
    for (std::uint64_t k = 0; k < n; ++k) insert(k);
    for (std::uint64_t k = 0; k < m; ++k) remove(k);
  } else {
    // Removal of insertion k goes right after insertion slot[k] = k + d, d
    // uniform in [0, min(window, n-1-k)]; removals sharing a slot come in
    // increasing k. Counting sort by slot keeps this O(n).
    Rng sched(o.seed, 1);
    std::vector<std::uint64_t> slot(static_cast<std::size_t>(m));
    std::vector<std::uint64_t> start(static_cast<std::size_t>(n + 1), 0);
    for (std::uint64_t k = 0; k < m; ++k) {
      const std::uint64_t span = std::min(kInterleaveWindow, n - 1 - k);
      slot[k] = k + sched.below(span + 1);
      ++start[slot[k] + 1];
    }
    for (std::uint64_t j = 0; j < n; ++j) start[j + 1] += start[j];
    std::vector<std::uint64_t> order(static_cast<std::size_t>(m));
    {
      std::vector<std::uint64_t> fill(start.begin(), start.end() - 1);
      for (std::uint64_t k = 0; k < m; ++k) order[fill[slot[k]]++] = k;
    }
    for (std::uint64_t j = 0; j < n; ++j) {
      insert(j);
      for (std::uint64_t i = start[j]; i < start[j + 1]; ++i) remove(order[i]);
    }
  }
  return st;
}

Distribution parse_distribution(const std::string& name) {
  for (Distribution d : {Distribution::uniform, Distribution::normal, Distribution::line, Distribution::grid,
                         Distribution::sphere, Distribution::corner, Distribution::kuzmin, Distribution::front_x,
                         Distribution::front_y, Distribution::front_z, Distribution::clusters})
    if (name == to_string(d)) return d;
  throw Error(ErrorCode::invalid_argument, "unknown distribution '" + name +
                                               "'; expected uniform, normal, line, grid, sphere, corner, kuzmin, "
                                               "front_x, front_y, front_z or clusters");
}

const char* to_string(Distribution d) {
  switch (d) {
    case Distribution::uniform: return "uniform";
    case Distribution::normal: return "normal";
    case Distribution::line: return "line";
    case Distribution::grid: return "grid";
    case Distribution::sphere: return "sphere";
    case Distribution::corner: return "corner";
    case Distribution::kuzmin: return "kuzmin";
    case Distribution::front_x: return "front_x";
    case Distribution::front_y: return "front_y";
    case Distribution::front_z: return "front_z";
    case Distribution::clusters: return "clusters";
  }
  return "unknown";
}

}  // namespace pdt
