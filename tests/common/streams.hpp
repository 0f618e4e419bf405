// SPDX-License-Identifier: MIT
#pragma once
// Operation streams for the tests: generated ones, streams over given points
// with removals interleaved or after, the points a stream leaves standing,
// and a sequential replay (the reference an engine run must equal).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <catch2/catch.hpp>

#include "common/point_sets.hpp"
#include "pdt/generate.hpp"
#include "pdt/ops.hpp"
#include "pdt/triangulation.hpp"

namespace pdt_test {

inline pdt::OpStream generated(pdt::Distribution dist, std::uint64_t n, double remove_fraction, pdt::RemovalOrder order,
                        std::uint64_t seed = 7) {
  pdt::GenerateOptions o;
  o.dist = dist;
  o.points = n;
  o.remove_fraction = remove_fraction;
  o.removal_order = order;
  o.seed = seed;
  return pdt::generate(o);
}

// A stream inserting pts in order; the first floor(F * n) insertions are undone,
// insertion k's removal right after insertion k + d, d uniform in
// [0, min(1024, n-1-k)] (generate's interleaved order), or all at the end.
inline pdt::OpStream stream_of(const std::vector<pdt::Point3>& pts, double remove_fraction, std::uint64_t seed,
                        bool interleaved = true) {
  const std::size_t n = pts.size();
  const auto m = static_cast<std::size_t>(std::floor(remove_fraction * static_cast<double>(n)));
  std::vector<std::vector<std::uint64_t>> after(n);
  std::mt19937_64 rng(seed);
  for (std::size_t k = 0; k < m; ++k) {
    std::size_t at = n - 1;
    if (interleaved) at = k + rng() % (std::min<std::size_t>(1024, n - 1 - k) + 1);
    after[at].push_back(k);
  }
  pdt::OpStream s;
  s.box = bounding_box(pts);
  for (std::size_t i = 0; i < n; ++i) {
    pdt::Operation ins;
    ins.kind = pdt::Operation::Kind::insert;
    ins.point = pts[i];
    s.ops.push_back(ins);
    for (std::uint64_t k : after[i]) {
      pdt::Operation rem;
      rem.kind = pdt::Operation::Kind::remove;
      rem.target = k;
      s.ops.push_back(rem);
    }
  }
  return s;
}

// The points whose insertions the stream leaves standing (with repetitions).
inline std::vector<pdt::Point3> survivors(const pdt::OpStream& s) {
  std::vector<pdt::Point3> pts;
  std::vector<bool> alive;
  for (const auto& op : s.ops) {
    if (op.kind == pdt::Operation::Kind::insert) {
      pts.push_back(op.point);
      alive.push_back(true);
    } else {
      REQUIRE(op.target < alive.size());
      REQUIRE(alive[op.target]);
      alive[op.target] = false;
    }
  }
  std::vector<pdt::Point3> out;
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (alive[i]) out.push_back(pts[i]);
  return out;
}

inline void replay_sequential(pdt::Triangulation& t, const pdt::OpStream& s) {
  std::vector<pdt::VertexId> ids;
  for (const auto& op : s.ops) {
    if (op.kind == pdt::Operation::Kind::insert)
      ids.push_back(t.insert(op.point).vertex);
    else
      t.remove(ids.at(op.target));
  }
}

}  // namespace pdt_test
