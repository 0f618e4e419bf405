// SPDX-License-Identifier: MIT
// Uses only the installed public headers and pdt::pdt; exits nonzero on any mismatch.
#include <pdt/pdt.hpp>

#include <cstdio>
#include <limits>

namespace {
int failures = 0;
void expect(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "pdt_consumer: FAILED: %s\n", what);
    ++failures;
  }
}
}  // namespace

int main() {
  pdt::Triangulation t;
  // The corners of a tetrahedron and its centroid: the centroid splits it into 4.
  const pdt::Point3 pts[] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.25, 0.25, 0.25}};
  for (const auto& p : pts) t.insert(p);
  expect(t.dimension() == 3, "dimension() == 3");
  expect(t.number_of_vertices() == 5, "number_of_vertices() == 5");
  expect(t.number_of_finite_cells() == 4, "number_of_finite_cells() == 4");

  // pdt::Error must cross the library boundary with its type intact.
  bool threw = false;
  try {
    t.insert({std::numeric_limits<double>::quiet_NaN(), 0, 0});
  } catch (const pdt::Error& e) {
    threw = e.code() == pdt::ErrorCode::non_finite_coordinate;
  }
  expect(threw, "insert(NaN) throws pdt::Error(non_finite_coordinate)");
  expect(t.number_of_finite_cells() == 4, "a failed insert changes nothing");

  if (failures == 0) std::printf("pdt_consumer: ok (%zu finite cells)\n", t.number_of_finite_cells());
  return failures == 0 ? 0 : 1;
}
