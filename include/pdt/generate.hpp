// SPDX-License-Identifier: MIT
#pragma once
// Synthetic operation streams, as in the paper's §4.1 plus the degenerate cases.
#include <cstdint>
#include <string>

#include "pdt/ops.hpp"

namespace pdt {

// Box of the stream: the unit cube for uniform, normal and line; [0, k-1]^3
// for grid; [-R, R]^3 for sphere.
enum class Distribution {
  uniform,  // uniform in the unit cube
  normal,   // normal around the cube's centre (sigma 0.15), coordinates outside [0,1] redrawn
  line,     // around the line y = z = 0.5: x uniform, distance r = 0.5 u^3 (u uniform), angle uniform
  grid,     // integer lattice {0..k-1}^3, k^3 >= N smallest, N of it in shuffled order:
            // many cospherical and coplanar subsets; coordinates are small integers
  sphere,   // integer points exactly on a sphere x^2+y^2+z^2 = R^2 (R the smallest radius with
            // at least N of them), N of them in shuffled order: all cospherical
  // Skewed streams (load balance): the work concentrates or moves.
  corner,   // uniform in [0, 0.45]^3, a corner of the unit-cube domain
  kuzmin,   // a Kuzmin-like cluster around the cube's centre: distance r = a sqrt((1-u)^-2 - 1),
            // a = 0.05, u uniform, direction uniform; points outside [0,1]^3 redrawn
  front_x,  // uniform in the unit cube, streamed in increasing x: a front sweeping the domain
  front_y,  // the same, in increasing y
  front_z,  // the same, in increasing z
  clusters,  // every other point uniform in the unit cube, the rest alternately in the cubes
             // of side 1e-4 at (0.2, 0.2, 0.2) and (0.7, 0.7, 0.7): two clusters far smaller
             // than the domain, amid a uniform cloud
};

// The first floor(F * N) insertions (F = remove_fraction, taken as the decimal
// it was written as: 0.29 of 100 is 29) are undone:
enum class RemovalOrder {
  after,       // paper §4.1: all insertions, then the removals, in insertion order
  interleaved  // a refiner's pattern: the removal of insertion k comes right after
               // insertion k + d, d uniform in [0, min(1024, N-1-k)]
};

struct GenerateOptions {
  // The most points generate() makes: vertex ids are 32-bit, and the grid
  // indexes its lattice with 32-bit integers (k <= 1625, k^3 < 2^32).
  static constexpr std::uint64_t max_points = (std::uint64_t{1} << 32) - (std::uint64_t{1} << 23);
  Distribution dist = Distribution::uniform;
  std::uint64_t points = 1000;
  double remove_fraction = 0;  // in [0, 1]
  RemovalOrder removal_order = RemovalOrder::after;
  std::uint64_t seed = 1;
};

// Deterministic for given options (its own PRNG, independent of the platform's
// <random> distributions and of libm): the same stream on every platform. The
// points depend only on dist, points and seed, not on the removal options. The
// stream carries the box that holds its points. Throws pdt::Error(invalid_argument)
// for remove_fraction outside [0, 1] or an absurd number of points (> ~4.29e9).
// sphere enumerates the sphere's lattice points in O(R^2): fine up to ~1e6 points.
OpStream generate(const GenerateOptions& options);
Distribution parse_distribution(const std::string& name);  // throws pdt::Error(invalid_argument)
const char* to_string(Distribution d);

}  // namespace pdt
