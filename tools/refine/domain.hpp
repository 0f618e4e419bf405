// SPDX-License-Identifier: MIT
#pragma once
// The domains pdt refine meshes: implicit shapes, inside where f(p) < 0, and
// the points that sample their boundary surface.
//   sphere  centre at the origin, radius 1
//   torus   axis z, centre at the origin, major radius 1, minor radius 0.4
//   gyroid  a gyroid slab in the cube [-1, 1]^3: |sin x cos y + sin y cos z +
//           sin z cos x| < 0.6 at frequency pi: non-convex, multiply connected
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "pdt/geometry.hpp"

namespace pdt_refine {

struct Domain {
  std::string name;
  pdt::Box box;  // holds the domain, with a margin
  // Signed function, < 0 inside, about the distance to the surface near it.
  double (*f)(const pdt::Point3&);
  int label = 1;  // the label written for the domain's tetrahedra
  // L with |f(p) - f(q)| <= L |p - q| everywhere (1 for a distance function),
  // or 0 if none is known: lets surface_samples skip regions far from the
  // surface without changing its result.
  double lipschitz = 0;
  // Optional: a function <= f with Lipschitz constant 1 (the gyroid's cube),
  // so that blocks far outside are skipped even without a bound on f.
  double (*outside_bound)(const pdt::Point3&) = nullptr;
  // Optional: true only if f has one sign (< 0, or >= 0) on the whole ball
  // of radius reach around c, for a domain whose f has no Lipschitz bound
  // (the gyroid's, divided by its gradient), so that blocks inside or
  // outside it are skipped all the same.
  bool (*uncrossed)(const pdt::Point3& c, double reach) = nullptr;
};

// The domain called name; throws pdt::Error(invalid_argument) listing the
// known ones for any other name.
Domain domain_by_name(const std::string& name);
const char* domain_names();  // "sphere, torus, gyroid"

// Points on the domain's surface, about `spacing` apart and never closer than
// spacing / 2 to each other: a grid of cells of that size, each cell the
// surface crosses projected onto the surface (Newton steps on f), then thinned
// in an order drawn from the seed (the seed picks which ones stay). With a
// Lipschitz bound (or an outside bound, or `uncrossed`), blocks of cells the
// surface cannot reach are skipped whole (same result), so the time follows
// the surface's cells, not the box's.
// More than max_candidates crossed cells: stops there and sets *too_many
// (the samples are then not the surface's; a caller with a point budget
// passes a cap above which the samples alone would exceed it).
std::vector<pdt::Point3> surface_samples(const Domain& d, double spacing, std::uint64_t seed,
                                         std::size_t max_candidates = SIZE_MAX, bool* too_many = nullptr);

}  // namespace pdt_refine
