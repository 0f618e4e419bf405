// SPDX-License-Identifier: MIT
#pragma once
// Test helpers: CGAL's Delaunay_triangulation_3 (Epick) as the reference that
// pdt::Triangulation must equal tetrahedron for tetrahedron, and canonical
// (order- and id-independent) forms of both to compare them.
//
// Canonical form: a tetrahedron is the sorted array of the indices of its 4
// points in a reference point list (the first occurrence of each distinct
// point); the list of tetrahedra is sorted. Two triangulations of the same
// point set are equal iff their canonical forms are.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <catch2/catch.hpp>

#include "pdt/error.hpp"
#include "pdt/geometry.hpp"
#include "pdt/triangulation.hpp"

#ifndef PDT_SHARED_DATA
#define PDT_SHARED_DATA "../shared/data"
#endif

namespace pdt_test {

using Tet = std::array<std::uint32_t, 4>;
using TetList = std::vector<Tet>;

using CKernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using CPoint = CKernel::Point_3;
using CVb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, CKernel>;
using CTds = CGAL::Triangulation_data_structure_3<CVb, CGAL::Delaunay_triangulation_cell_base_3<CKernel>>;
using CDelaunay = CGAL::Delaunay_triangulation_3<CKernel, CTds>;

inline CPoint to_cgal(const pdt::Point3& p) { return CPoint(p.x, p.y, p.z); }

// Hash consistent with Point3::operator== (so -0.0 and +0.0 hash alike).
struct PointHash {
  static std::uint64_t bits(double d) {
    d += 0.0;  // -0.0 -> +0.0
    std::uint64_t u;
    std::memcpy(&u, &d, sizeof u);
    return u;
  }
  std::size_t operator()(const pdt::Point3& p) const {
    std::uint64_t h = bits(p.x) * 0x9E3779B97F4A7C15ull;
    h ^= bits(p.y) + 0x7F4A7C159E3779B9ull + (h << 6) + (h >> 2);
    h ^= bits(p.z) + 0x94D049BB133111EBull + (h << 6) + (h >> 2);
    return static_cast<std::size_t>(h ^ (h >> 31));
  }
};

// Maps each distinct point to the index of its first occurrence in a list.
using PointIndex = std::unordered_map<pdt::Point3, std::uint32_t, PointHash>;

inline PointIndex make_point_index(const std::vector<pdt::Point3>& pts) {
  PointIndex index;
  index.reserve(pts.size() * 2);
  for (std::uint32_t i = 0; i < pts.size(); ++i) index.emplace(pts[i], i);
  return index;
}

inline void canonicalize(TetList& tets) {
  for (auto& t : tets) std::sort(t.begin(), t.end());
  std::sort(tets.begin(), tets.end());
}

struct CgalResult {
  int dimension = -1;
  std::size_t vertices = 0;  // distinct finite vertices
  std::size_t cells = 0;     // finite + infinite (0 while dimension < 3)
  TetList tets;              // canonical, indices into the input list
};

// CGAL's Delaunay triangulation of pts; each tetrahedron given by the indices
// (first occurrence) of its points in pts.
inline CgalResult cgal_reference(const std::vector<pdt::Point3>& pts) {
  std::vector<std::pair<CPoint, std::uint32_t>> unique;
  {
    PointIndex seen;
    seen.reserve(pts.size() * 2);
    unique.reserve(pts.size());
    for (std::uint32_t i = 0; i < pts.size(); ++i)
      if (seen.emplace(pts[i], i).second) unique.emplace_back(to_cgal(pts[i]), i);
  }
  CDelaunay dt(unique.begin(), unique.end());
  CgalResult r;
  r.dimension = dt.dimension();
  r.vertices = dt.number_of_vertices();
  if (dt.dimension() == 3) {
    r.cells = dt.number_of_cells();
    r.tets.reserve(dt.number_of_finite_cells());
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c)
      r.tets.push_back({c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()});
  }
  canonicalize(r.tets);
  return r;
}

inline TetList cgal_tets(const std::vector<pdt::Point3>& pts) { return cgal_reference(pts).tets; }

// pdt's finite cells in canonical form, each vertex mapped through its point
// to the reference index. A vertex whose point is not in the index maps to
// 0xFFFFFFFF (so the comparison fails visibly).
inline TetList canonical_tets(const pdt::Triangulation& t, const PointIndex& index) {
  std::vector<std::uint32_t> of_vertex(t.vertex_id_bound(), 0xFFFFFFFFu);
  for (pdt::VertexId v : t.vertices()) {
    auto it = index.find(t.point(v));
    if (it != index.end()) of_vertex.at(v) = it->second;
  }
  TetList tets;
  auto cells = t.finite_cells();
  tets.reserve(cells.size());
  for (const auto& c : cells) {
    Tet tet;
    for (int i = 0; i < 4; ++i) tet[i] = c[i] < of_vertex.size() ? of_vertex[c[i]] : 0xFFFFFFFFu;
    tets.push_back(tet);
  }
  canonicalize(tets);
  return tets;
}

inline TetList canonical_tets(const pdt::Triangulation& t, const std::vector<pdt::Point3>& pts) {
  return canonical_tets(t, make_point_index(pts));
}

// The points of the live vertices, in increasing id order.
inline std::vector<pdt::Point3> surviving_points(const pdt::Triangulation& t) {
  std::vector<pdt::Point3> pts;
  for (pdt::VertexId v : t.vertices()) pts.push_back(t.point(v));
  return pts;
}

inline std::string str(const pdt::Point3& p) {
  std::ostringstream os;
  os.precision(17);
  os << "(" << p.x << ", " << p.y << ", " << p.z << ")";
  return os.str();
}

// A few tetrahedra in a but not in b, with their coordinates.
inline std::string describe_difference(const TetList& a, const TetList& b, const std::vector<pdt::Point3>& pts,
                                       const char* what, std::size_t max_shown = 5) {
  TetList only;
  std::set_difference(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(only));
  std::ostringstream os;
  os << only.size() << " tets only in " << what;
  for (std::size_t k = 0; k < only.size() && k < max_shown; ++k) {
    os << "\n  [";
    for (int i = 0; i < 4; ++i) {
      std::uint32_t idx = only[k][i];
      os << (i ? " " : "") << idx;
      if (idx < pts.size()) os << str(pts[idx]);
    }
    os << "]";
  }
  return os.str();
}

inline std::string describe_mismatch(const TetList& got, const TetList& want, const std::vector<pdt::Point3>& pts) {
  std::ostringstream os;
  os << "pdt: " << got.size() << " tets, CGAL: " << want.size() << " tets\n"
     << describe_difference(got, want, pts, "pdt") << "\n"
     << describe_difference(want, got, pts, "CGAL");
  return os.str();
}

// Every finite cell of t positively oriented (CGAL::orientation).
inline bool all_positively_oriented(const pdt::Triangulation& t, std::string* why = nullptr) {
  for (const auto& c : t.finite_cells()) {
    auto o = CGAL::orientation(to_cgal(t.point(c[0])), to_cgal(t.point(c[1])), to_cgal(t.point(c[2])),
                               to_cgal(t.point(c[3])));
    if (o != CGAL::POSITIVE) {
      if (why) {
        std::ostringstream os;
        os << "cell (" << c[0] << "," << c[1] << "," << c[2] << "," << c[3] << ") has orientation " << int(o);
        *why = os.str();
      }
      return false;
    }
  }
  return true;
}

// t.validate() holds; otherwise fails with what it reported.
inline void require_valid(const pdt::Triangulation& t) {
  std::string why;
  const bool ok = t.validate(&why);
  INFO("validate: " << why);
  REQUIRE(ok);
}

// REQUIREs that t is CGAL's Delaunay triangulation of its own live vertices:
// same dimension, same number of vertices and cells, same tetrahedra, and
// every finite cell positively oriented.
inline void require_same_as_cgal(const pdt::Triangulation& t) {
  const std::vector<pdt::Point3> pts = surviving_points(t);
  const CgalResult ref = cgal_reference(pts);
  INFO("points: " << pts.size());
  // Distinct live vertices (two pdt vertices at one point would shrink CGAL's count).
  REQUIRE(ref.vertices == pts.size());
  REQUIRE(t.number_of_vertices() == pts.size());
  REQUIRE(t.dimension() == ref.dimension);
  const TetList got = canonical_tets(t, pts);
  const bool same = got == ref.tets;
  std::string mismatch = same ? std::string() : "triangulation differs from CGAL's\n" + describe_mismatch(got, ref.tets, pts);
  INFO(mismatch);
  REQUIRE(same);
  REQUIRE(t.number_of_finite_cells() == ref.tets.size());
  if (ref.dimension == 3) REQUIRE(t.number_of_cells() == ref.cells);
  std::string why;
  const bool oriented = all_positively_oriented(t, &why);
  INFO(why);
  REQUIRE(oriented);
}

// As above, and t's vertex set must be exactly the distinct points of
// `expected` (what the caller's own bookkeeping says should survive).
inline void require_same_as_cgal(const pdt::Triangulation& t, const std::vector<pdt::Point3>& expected) {
  std::vector<pdt::Point3> want;
  {
    PointIndex seen;
    for (const auto& p : expected)
      if (seen.emplace(p, 0).second) want.push_back(p);
  }
  std::vector<pdt::Point3> have = surviving_points(t);
  auto lex = [](const pdt::Point3& a, const pdt::Point3& b) {
    return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
  };
  std::sort(want.begin(), want.end(), lex);
  std::sort(have.begin(), have.end(), lex);
  INFO("expected " << want.size() << " distinct points, triangulation has " << have.size() << " vertices");
  REQUIRE((have == want));
  require_same_as_cgal(t);
}

// -- small utilities shared by the test files ---------------------------------

// Fisher-Yates with our own index draw (platform-independent, unlike std::shuffle).
template <class T>
inline void shuffle(std::vector<T>& v, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  for (std::size_t i = v.size(); i > 1; --i) {
    std::size_t j = static_cast<std::size_t>(rng() % i);
    std::swap(v[i - 1], v[j]);
  }
}

// Uniform double in [lo, hi) from a 64-bit generator (platform-independent).
inline double uniform(std::mt19937_64& rng, double lo, double hi) {
  return lo + (hi - lo) * (static_cast<double>(rng() >> 11) * 0x1.0p-53);
}

inline std::vector<pdt::Point3> random_points(std::size_t n, std::uint64_t seed, double lo = 0, double hi = 1) {
  std::mt19937_64 rng(seed);
  std::vector<pdt::Point3> pts(n);
  for (auto& p : pts) p = {uniform(rng, lo, hi), uniform(rng, lo, hi), uniform(rng, lo, hi)};
  return pts;
}

// Inserts pts in order into t; returns the vertex id of each insertion.
inline std::vector<pdt::VertexId> insert_all(pdt::Triangulation& t, const std::vector<pdt::Point3>& pts) {
  std::vector<pdt::VertexId> ids;
  ids.reserve(pts.size());
  for (const auto& p : pts) ids.push_back(t.insert(p).vertex);
  return ids;
}

inline std::string shared_data(const std::string& rel) { return std::string(PDT_SHARED_DATA) + "/" + rel; }

}  // namespace pdt_test
