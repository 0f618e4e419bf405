// SPDX-License-Identifier: MIT
// Synthetic streams: determinism (pinned values guard platform independence),
// every point inside the stream's box, the shape of each distribution, exact
// integer grids and spheres, and the removal schedules.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <set>
#include <tuple>
#include <vector>

#include "common/io_test_util.hpp"
#include "pdt/generate.hpp"

using pdt_test::catch_error;
using pdt_test::same_bits;

namespace {

pdt::OpStream gen(pdt::Distribution d, std::uint64_t n, std::uint64_t seed = 1, double f = 0,
                  pdt::RemovalOrder order = pdt::RemovalOrder::after) {
  pdt::GenerateOptions o;
  o.dist = d;
  o.points = n;
  o.seed = seed;
  o.remove_fraction = f;
  o.removal_order = order;
  return pdt::generate(o);
}

std::vector<pdt::Point3> points_of(const pdt::OpStream& s) {
  std::vector<pdt::Point3> p;
  for (const auto& op : s.ops)
    if (op.kind == pdt::Operation::Kind::insert) p.push_back(op.point);
  return p;
}

bool identical(const pdt::OpStream& a, const pdt::OpStream& b) {
  if (a.ops.size() != b.ops.size()) return false;
  for (std::size_t i = 0; i < a.ops.size(); ++i) {
    if (a.ops[i].kind != b.ops[i].kind) return false;
    if (a.ops[i].kind == pdt::Operation::Kind::insert ? !same_bits(a.ops[i].point, b.ops[i].point)
                                                      : a.ops[i].target != b.ops[i].target)
      return false;
  }
  return true;
}

const pdt::Distribution kAll[] = {pdt::Distribution::uniform, pdt::Distribution::normal,  pdt::Distribution::line,
                                  pdt::Distribution::grid,    pdt::Distribution::sphere,  pdt::Distribution::corner,
                                  pdt::Distribution::kuzmin,  pdt::Distribution::front_x, pdt::Distribution::front_y,
                                  pdt::Distribution::front_z, pdt::Distribution::clusters};

bool is_integer(double v) { return std::floor(v) == v && std::abs(v) < 1e9; }

}  // namespace

TEST_CASE("generate is deterministic, and seeds matter", "[gen]") {
  for (auto d : kAll) {
    INFO(pdt::to_string(d));
    const auto a = gen(d, 2000, 7, 0.3, pdt::RemovalOrder::interleaved);
    const auto b = gen(d, 2000, 7, 0.3, pdt::RemovalOrder::interleaved);
    CHECK(identical(a, b));
    const auto c = gen(d, 2000, 8, 0.3, pdt::RemovalOrder::interleaved);
    CHECK_FALSE(identical(a, c));
  }
}

TEST_CASE("generate gives the same bits on every platform (pinned values)", "[gen]") {
  // Computed once; any change of PRNG, sampler or arithmetic shows up here.
  // The samplers use only IEEE-exact operations, so these hold everywhere.
  const auto u = points_of(gen(pdt::Distribution::uniform, 3, 1));
  CHECK(same_bits(u[0], pdt::Point3{0.70292183315885048, 0.52043661993885693, 0.5741057000197225}));
  const auto nrm = points_of(gen(pdt::Distribution::normal, 3, 1));
  CHECK(same_bits(nrm[2], pdt::Point3{0.40140586201467421, 0.47269055505002078, 0.66244221370961109}));
  const auto ln = points_of(gen(pdt::Distribution::line, 3, 1));
  CHECK(same_bits(ln[1], pdt::Point3{0.69717841655996149, 0.49857397327249831, 0.49960500695875343}));
  const auto g = points_of(gen(pdt::Distribution::grid, 3, 1));
  CHECK(same_bits(g[0], pdt::Point3{1, 0, 1}));
  const auto sp = points_of(gen(pdt::Distribution::sphere, 100, 1));
  CHECK(same_bits(sp[0], pdt::Point3{-3, -6, -6}));
}

TEST_CASE("every generated point lies in the stream's box", "[gen]") {
  for (auto d : kAll) {
    INFO(pdt::to_string(d));
    const auto s = gen(d, 5000, 3);
    REQUIRE(s.box.has_value());
    CHECK(s.insert_count() == 5000);
    CHECK(s.remove_count() == 0);
    for (const auto& p : points_of(s)) {
      REQUIRE(std::isfinite(p.x));
      REQUIRE(s.box->contains(p));
    }
  }
}

TEST_CASE("uniform, normal and line have their documented shapes", "[gen]") {
  const std::size_t n = 20000;
  SECTION("uniform fills the unit cube") {
    const auto p = points_of(gen(pdt::Distribution::uniform, n));
    double mean = 0;
    int low_octant = 0;
    for (const auto& q : p) {
      CHECK((q.x >= 0 && q.x < 1 && q.y >= 0 && q.y < 1 && q.z >= 0 && q.z < 1));
      mean += q.x + q.y + q.z;
      low_octant += q.x < 0.5 && q.y < 0.5 && q.z < 0.5;
    }
    CHECK(mean / (3.0 * n) == Approx(0.5).margin(0.01));
    CHECK(low_octant / double(n) == Approx(0.125).margin(0.01));
  }
  SECTION("normal: mean 0.5, sigma about 0.15") {
    const auto p = points_of(gen(pdt::Distribution::normal, n));
    double sum = 0, sq = 0;
    int within_one_sigma = 0;
    for (const auto& q : p)
      for (double c : {q.x, q.y, q.z}) {
        sum += c;
        sq += (c - 0.5) * (c - 0.5);
        within_one_sigma += std::abs(c - 0.5) <= 0.15;
      }
    const double m = sum / (3.0 * n), sd = std::sqrt(sq / (3.0 * n));
    CHECK(m == Approx(0.5).margin(0.005));
    CHECK(sd == Approx(0.15).margin(0.005));  // truncation at 3.3 sigma barely narrows it
    CHECK(within_one_sigma / (3.0 * n) == Approx(0.6827).margin(0.01));
  }
  SECTION("line: distance 0.5 u^3 from y = z = 0.5") {
    const auto p = points_of(gen(pdt::Distribution::line, n));
    std::vector<double> r;
    double xmean = 0;
    int upper = 0;
    for (const auto& q : p) {
      r.push_back(std::hypot(q.y - 0.5, q.z - 0.5));
      xmean += q.x;
      upper += q.y > 0.5;
    }
    std::sort(r.begin(), r.end());
    CHECK(r.back() <= 0.5 + 1e-15);
    CHECK(r[n / 2] == Approx(0.0625).margin(0.005));       // median of 0.5 u^3 = 0.5/8
    CHECK(r[n / 10] == Approx(0.5 * 0.001).margin(0.0003)); // 10% quantile: 0.5 * 0.1^3
    CHECK(xmean / n == Approx(0.5).margin(0.01));
    CHECK(upper / double(n) == Approx(0.5).margin(0.02));   // angles uniform
  }
}

TEST_CASE("grid points are distinct small integers of the smallest lattice", "[gen]") {
  for (std::uint64_t n : {1ull, 2ull, 8ull, 9ull, 1000ull, 1001ull, 4321ull}) {
    INFO("n = " << n);
    const auto s = gen(pdt::Distribution::grid, n, 5);
    const auto p = points_of(s);
    REQUIRE(p.size() == n);
    const double k = s.box->hi.x + 1;
    CHECK(s.box->lo.x == 0);
    CHECK(k * k * k >= double(n));
    CHECK((k - 1) * (k - 1) * (k - 1) < double(n));
    std::set<std::tuple<double, double, double>> seen;
    for (const auto& q : p) {
      CHECK((is_integer(q.x) && is_integer(q.y) && is_integer(q.z)));
      CHECK(s.box->contains(q));
      seen.insert({q.x, q.y, q.z});
    }
    CHECK(seen.size() == n);
  }
  // A perfect cube takes the whole lattice, in shuffled order.
  const auto p = points_of(gen(pdt::Distribution::grid, 1000, 5));
  CHECK_FALSE(std::is_sorted(p.begin(), p.end(), [](auto& a, auto& b) {
    return std::tie(a.z, a.y, a.x) < std::tie(b.z, b.y, b.x);
  }));
}

TEST_CASE("sphere points are exactly on the sphere (integer arithmetic)", "[gen]") {
  // Smallest radii: r3(1) = 6, r3(4) = 6, r3(9) = 30 (3^2 = 1+4+4 in 24 ways + 6).
  CHECK(gen(pdt::Distribution::sphere, 6).box->hi.x == 1);
  CHECK(gen(pdt::Distribution::sphere, 7).box->hi.x == 3);
  CHECK(gen(pdt::Distribution::sphere, 30).box->hi.x == 3);
  // Sizes across many radii; generate() also cross-checks its enumeration
  // against the r3 formula and throws if they differ.
  for (std::uint64_t n : {1ull, 6ull, 7ull, 31ull, 100ull, 999ull, 5000ull, 30000ull}) {
    INFO("n = " << n);
    const auto s = gen(pdt::Distribution::sphere, n, 11);
    const auto p = points_of(s);
    REQUIRE(p.size() == n);
    const auto R = static_cast<std::int64_t>(s.box->hi.x);
    CHECK(s.box->lo.x == -s.box->hi.x);
    std::set<std::tuple<std::int64_t, std::int64_t, std::int64_t>> seen;
    for (const auto& q : p) {
      REQUIRE((is_integer(q.x) && is_integer(q.y) && is_integer(q.z)));
      const auto x = static_cast<std::int64_t>(q.x), y = static_cast<std::int64_t>(q.y),
                 z = static_cast<std::int64_t>(q.z);
      REQUIRE(x * x + y * y + z * z == R * R);
      seen.insert({x, y, z});
    }
    CHECK(seen.size() == n);
  }
}

TEST_CASE("removal after the insertions: the first floor(F*N), in order", "[gen]") {
  const auto s = gen(pdt::Distribution::uniform, 1000, 2, 0.3333);
  REQUIRE(s.ops.size() == 1000 + 333);
  for (std::size_t i = 0; i < 1000; ++i) REQUIRE(s.ops[i].kind == pdt::Operation::Kind::insert);
  for (std::size_t i = 0; i < 333; ++i) {
    REQUIRE(s.ops[1000 + i].kind == pdt::Operation::Kind::remove);
    REQUIRE(s.ops[1000 + i].target == i);
  }
  CHECK(gen(pdt::Distribution::uniform, 10, 2, 1.0).remove_count() == 10);
  CHECK(gen(pdt::Distribution::uniform, 10, 2, 0.0).remove_count() == 0);
  CHECK(gen(pdt::Distribution::uniform, 10, 2, 0.19).remove_count() == 1);
  // F as written in decimal: the doubles nearest 0.29 and 0.57 are a little
  // below them, and their products with 100 a little below 29 and 57.
  CHECK(gen(pdt::Distribution::uniform, 100, 2, 0.29).remove_count() == 29);
  CHECK(gen(pdt::Distribution::uniform, 100, 2, 0.57).remove_count() == 57);
  CHECK(gen(pdt::Distribution::uniform, 100, 2, 0.58).remove_count() == 58);
  CHECK(gen(pdt::Distribution::uniform, 100, 2, 0.289).remove_count() == 28);
  CHECK(gen(pdt::Distribution::uniform, 3, 2, 0.9999).remove_count() == 2);
}

TEST_CASE("interleaved removal: each right after an insertion following its own", "[gen]") {
  const std::uint64_t n = 5000;
  const auto s = gen(pdt::Distribution::normal, n, 4, 0.5, pdt::RemovalOrder::interleaved);
  REQUIRE(s.insert_count() == n);
  REQUIRE(s.remove_count() == n / 2);
  std::vector<std::int64_t> removed_after(n, -1);  // insertions made when k was removed
  std::uint64_t made = 0;
  bool some_not_at_end = false;
  for (const auto& op : s.ops) {
    if (op.kind == pdt::Operation::Kind::insert) {
      ++made;
      continue;
    }
    REQUIRE(op.target < n / 2);
    REQUIRE(op.target < made);                 // after its insertion
    REQUIRE(removed_after[op.target] == -1);   // exactly once
    removed_after[op.target] = static_cast<std::int64_t>(made);
    CHECK(made - 1 - op.target <= 1024);       // the documented window
    some_not_at_end = some_not_at_end || made < n;
  }
  for (std::uint64_t k = 0; k < n / 2; ++k) REQUIRE(removed_after[k] != -1);
  CHECK(some_not_at_end);
  // Same points as without removals: the schedule has its own random stream.
  const auto p0 = points_of(gen(pdt::Distribution::normal, n, 4));
  const auto p1 = points_of(s);
  REQUIRE(p0.size() == p1.size());
  for (std::size_t i = 0; i < n; ++i) REQUIRE(same_bits(p0[i], p1[i]));
}

TEST_CASE("generated streams survive write_ops/read_ops", "[gen][io]") {
  pdt_test::TempDir d;
  for (auto d_ : kAll) {
    const auto s = gen(d_, 3000, 9, 0.4, pdt::RemovalOrder::interleaved);
    pdt::write_ops(d.file("g.ops"), s);
    pdt::write_ops(d.file("g.opsb"), s);
    CHECK(identical(s, pdt::read_ops(d.file("g.ops"))));
    CHECK(identical(s, pdt::read_ops(d.file("g.opsb"))));
  }
}

TEST_CASE("generate rejects bad options; distribution names round-trip", "[gen]") {
  for (double f : {-0.1, 1.5, std::nan("")}) {
    pdt::GenerateOptions o;
    o.remove_fraction = f;
    auto e = catch_error([&] { pdt::generate(o); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  }
  pdt::GenerateOptions big;
  big.points = std::uint64_t{1} << 40;
  auto e = catch_error([&] { pdt::generate(big); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  // Enumerators out of range (a cast, a bad file field): refused, as both say.
  pdt::GenerateOptions bad_order;
  bad_order.remove_fraction = 0.5;
  bad_order.removal_order = static_cast<pdt::RemovalOrder>(7);
  auto e3 = catch_error([&] { pdt::generate(bad_order); });
  REQUIRE(e3);
  CHECK(e3->code() == pdt::ErrorCode::invalid_argument);
  CHECK(std::string(e3->what()).find("removal order") != std::string::npos);
  pdt::GenerateOptions bad_dist;
  bad_dist.dist = static_cast<pdt::Distribution>(99);
  auto e4 = catch_error([&] { pdt::generate(bad_dist); });
  REQUIRE(e4);
  CHECK(e4->code() == pdt::ErrorCode::invalid_argument);
  for (auto d : kAll) CHECK(pdt::parse_distribution(pdt::to_string(d)) == d);
  auto e2 = catch_error([] { pdt::parse_distribution("gaussian"); });
  REQUIRE(e2);
  CHECK(e2->code() == pdt::ErrorCode::invalid_argument);
  CHECK(std::string(e2->what()).find("gaussian") != std::string::npos);
  // Zero points: an empty stream with a usable box.
  for (auto d : kAll) {
    const auto s = gen(d, 0);
    CHECK(s.ops.empty());
    REQUIRE(s.box.has_value());
    CHECK(s.box->lo.x <= s.box->hi.x);
  }
}
