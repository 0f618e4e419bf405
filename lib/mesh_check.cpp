// SPDX-License-Identifier: MIT
// pdt::check_mesh: is a Mesh a Delaunay tetrahedralization of its points?
//
// Independent of the triangulation code on purpose (it is what tests and
// `pdt check` use to judge it): plain arrays in, CGAL's exact predicates
// (Exact_predicates_inexact_constructions_kernel: orientation,
// side_of_oriented_sphere) for every geometric decision.
//
// What is checked, and why it suffices. Let the tets be T.
//  1. Indices in range, 4 distinct points per tet, no two points equal.
//  2. Orientation: all tets positive (or all negative: then read mirrored),
//     none flat.
//  3. Every facet belongs to 1 (boundary) or 2 (interior) tets, and an
//     interior facet's two opposite vertices lie strictly on opposite sides of
//     it: the tets do not overlap across any facet (local injectivity).
//  4. Every point is a vertex of some tet.
//  5. Boundary facets form a closed oriented surface (each boundary edge in
//     exactly two boundary facets, traversed in opposite directions) that is
//     locally convex at every edge, and the tets are connected through their
//     facets. With 3, the union of T is then a convex polytope covered d
//     times; 6 checks d = 1. The union contains every point (4), so it is
//     the convex hull. (When the hull facets times the points are few, each
//     hull facet is also tested against every point, literally.)
//  6. Degree 1: a point strictly inside one tet lies in exactly one tet.
//  7. Local Delaunay: for each interior facet the vertex opposite in one tet is
//     not strictly inside the circumsphere of the other. For a triangulation of
//     the convex hull, locally Delaunay everywhere implies Delaunay (Delaunay's
//     lemma). Cospherical ties are accepted: any Delaunay tetrahedralization
//     passes, not only the symbolically perturbed one.
// No tets at all is valid exactly when the points do not span 3D (then there
// is no tetrahedralization), or there are none.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "pdt/io.hpp"
#include "point_checks.hpp"

namespace pdt {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using P3 = K::Point_3;

// Facet f of a tet: the 3 vertices other than vertex f.
constexpr int kFacet[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};

struct FacetRec {
  std::uint32_t v[3];  // sorted
  std::uint32_t ref;   // 4 * tet + facet
  bool operator<(const FacetRec& o) const {
    if (v[0] != o.v[0]) return v[0] < o.v[0];
    if (v[1] != o.v[1]) return v[1] < o.v[1];
    if (v[2] != o.v[2]) return v[2] < o.v[2];
    return ref < o.ref;
  }
  bool same(const FacetRec& o) const { return v[0] == o.v[0] && v[1] == o.v[1] && v[2] == o.v[2]; }
};

struct EdgeRec {
  std::uint32_t a, b;  // a < b
  bool forward;        // the facet runs a -> b
  std::uint32_t facet; // index into the boundary facet list
  std::uint32_t third; // the facet's third vertex
  bool operator<(const EdgeRec& o) const {
    if (a != o.a) return a < o.a;
    if (b != o.b) return b < o.b;
    return facet < o.facet;
  }
};

struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(std::uint32_t a, std::uint32_t b) { parent[find(a)] = find(b); }
};

std::string tet_str(std::size_t t) { return "tetrahedron " + std::to_string(t); }
std::string pt_str(std::size_t p) { return "point " + std::to_string(p); }

MeshCheck fail(MeshCheck r, std::string why) {
  r.valid = false;
  r.message = std::move(why);
  return r;
}

}  // namespace

MeshCheck check_mesh(const Mesh& mesh) {
  MeshCheck r;
  r.points = mesh.points.size();
  r.tets = mesh.tets.size();
  const std::size_t np = mesh.points.size(), nt = mesh.tets.size();
  if (np >= 0xFFFFFFFFu || nt >= (std::size_t{1} << 30)) return fail(r, "mesh too large to check");

  std::vector<P3> P;
  P.reserve(np);
  for (std::size_t i = 0; i < np; ++i) {
    const Point3& p = mesh.points[i];
    if (!detail::is_finite(p))
      return fail(r, pt_str(i) + " has a NaN or infinite coordinate");
    P.emplace_back(p.x, p.y, p.z);
  }
  // 1. no two points equal (a Delaunay tetrahedralization has distinct vertices).
  {
    std::vector<std::uint32_t> order(np);
    std::iota(order.begin(), order.end(), 0u);
    auto key = [&](std::uint32_t i) { return std::array<double, 3>{mesh.points[i].x, mesh.points[i].y, mesh.points[i].z}; };
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
    for (std::size_t i = 1; i < np; ++i)
      if (mesh.points[order[i - 1]] == mesh.points[order[i]])
        return fail(r, pt_str(std::min(order[i - 1], order[i])) + " and " + pt_str(std::max(order[i - 1], order[i])) +
                           " coincide");
  }

  if (nt == 0) {
    if (np == 0) {
      r.valid = true;
      r.message = "empty mesh";
      return r;
    }
    // Valid only if the points span less than 3D: find 4 affinely independent.
    std::size_t b1 = np, b2 = np;
    for (std::size_t i = 1; i < np && b1 == np; ++i)
      if (P[i] != P[0]) b1 = i;
    for (std::size_t i = 1; b1 != np && i < np && b2 == np; ++i)
      if (!CGAL::collinear(P[0], P[b1], P[i])) b2 = i;
    for (std::size_t i = 1; b2 != np && i < np; ++i)
      if (CGAL::orientation(P[0], P[b1], P[b2], P[i]) != CGAL::COPLANAR)
        return fail(r, "no tetrahedra, but the points span 3D (" + pt_str(i) + " is off the plane of points 0, " +
                           std::to_string(b1) + ", " + std::to_string(b2) + ")");
    r.valid = true;
    const std::string points = b1 == np ? "a single point"
                               : "the " + std::to_string(np) + " points are " + (b2 == np ? "collinear" : "coplanar");
    r.message = "no tetrahedra; " + points + ", so none is expected";
    return r;
  }

  // 1-2. indices, distinct vertices, orientation.
  std::vector<std::array<std::uint32_t, 4>> T(mesh.tets.begin(), mesh.tets.end());
  CGAL::Orientation want = CGAL::ZERO;
  for (std::size_t t = 0; t < nt; ++t) {
    const auto& c = T[t];
    for (int i = 0; i < 4; ++i) {
      if (c[static_cast<std::size_t>(i)] >= np)
        return fail(r, tet_str(t) + " uses " + pt_str(c[static_cast<std::size_t>(i)]) +
                           (np == 1 ? ", but there is only 1 point" : ", but there are only " + std::to_string(np) + " points"));
    }
    const CGAL::Orientation o = CGAL::orientation(P[c[0]], P[c[1]], P[c[2]], P[c[3]]);
    if (o == CGAL::COPLANAR) return fail(r, tet_str(t) + " is flat (its 4 points are coplanar or repeated)");
    if (want == CGAL::ZERO) want = o;
    if (o != want)
      return fail(r, tet_str(t) + " is " + (o == CGAL::POSITIVE ? "positively" : "negatively") +
                         " oriented, unlike tetrahedron 0: the tetrahedra are not consistently oriented");
  }
  const bool mirrored = want == CGAL::NEGATIVE;
  if (mirrored)
    for (auto& c : T) std::swap(c[0], c[1]);  // now all positive

  // 4. every point used.
  {
    std::vector<std::uint8_t> used(np, 0);
    for (const auto& c : T)
      for (auto v : c) used[v] = 1;
    for (std::size_t i = 0; i < np; ++i)
      if (!used[i]) return fail(r, pt_str(i) + " is not a vertex of any tetrahedron");
  }

  // 3. facets.
  std::vector<FacetRec> F;
  F.reserve(4 * nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (int f = 0; f < 4; ++f) {
      FacetRec fr;
      for (int k = 0; k < 3; ++k) fr.v[k] = T[t][static_cast<std::size_t>(kFacet[f][k])];
      std::sort(fr.v, fr.v + 3);
      fr.ref = static_cast<std::uint32_t>(4 * t + static_cast<std::size_t>(f));
      F.push_back(fr);
    }
  std::sort(F.begin(), F.end());
  UnionFind uf(nt);
  std::vector<std::array<std::uint32_t, 3>> boundary;  // oriented outward
  std::size_t interior = 0;
  for (std::size_t i = 0; i < F.size();) {
    std::size_t j = i + 1;
    while (j < F.size() && F[j].same(F[i])) ++j;
    const FacetRec& a = F[i];
    const std::size_t ta = a.ref / 4;
    const std::uint32_t da = T[ta][a.ref % 4];  // vertex opposite the facet in ta
    const P3 &p = P[a.v[0]], &q = P[a.v[1]], &s = P[a.v[2]];
    if (j - i > 2)
      return fail(r, "facet (" + std::to_string(a.v[0]) + ", " + std::to_string(a.v[1]) + ", " + std::to_string(a.v[2]) +
                         ") belongs to " + std::to_string(j - i) + " tetrahedra (" + tet_str(ta) + ", " +
                         tet_str(F[i + 1].ref / 4) + ", " + tet_str(F[i + 2].ref / 4) + ")");
    if (j - i == 2) {
      const FacetRec& b = F[i + 1];
      const std::size_t tb = b.ref / 4;
      if (ta == tb) return fail(r, tet_str(ta) + " has a repeated vertex");
      const std::uint32_t db = T[tb][b.ref % 4];
      const CGAL::Orientation oa = CGAL::orientation(p, q, s, P[da]);
      const CGAL::Orientation ob = CGAL::orientation(p, q, s, P[db]);
      if (oa == ob)
        return fail(r, tet_str(ta) + " and " + tet_str(tb) + " overlap: they lie on the same side of their common facet");
      uf.unite(static_cast<std::uint32_t>(ta), static_cast<std::uint32_t>(tb));
      // 7. local Delaunay, with ta positively oriented as stored.
      const auto& c = T[ta];
      if (CGAL::side_of_oriented_sphere(P[c[0]], P[c[1]], P[c[2]], P[c[3]], P[db]) == CGAL::ON_POSITIVE_SIDE)
        return fail(r, "not Delaunay: " + pt_str(db) + " (of " + tet_str(tb) + ") is strictly inside the circumsphere of " +
                           tet_str(ta) + ", across their common facet");
      ++interior;
    } else {
      // Boundary facet, oriented so that the tet (da) is on its negative side.
      std::array<std::uint32_t, 3> bf{a.v[0], a.v[1], a.v[2]};
      if (CGAL::orientation(p, q, s, P[da]) == CGAL::POSITIVE) std::swap(bf[1], bf[2]);
      boundary.push_back(bf);
    }
    i = j;
  }
  // 5a. connected through facets.
  for (std::size_t t = 1; t < nt; ++t)
    if (uf.find(static_cast<std::uint32_t>(t)) != uf.find(0))
      return fail(r, "the tetrahedra are not connected through facets (" + tet_str(t) + " is cut off from tetrahedron 0)");
  // 5b. closed, oriented, locally convex boundary.
  if (boundary.size() >= 0xFFFFFFFFu) return fail(r, "mesh too large to check");
  std::vector<EdgeRec> E;
  E.reserve(3 * boundary.size());
  for (std::size_t f = 0; f < boundary.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t u = boundary[f][static_cast<std::size_t>(k)];
      const std::uint32_t v = boundary[f][static_cast<std::size_t>((k + 1) % 3)];
      const std::uint32_t w = boundary[f][static_cast<std::size_t>((k + 2) % 3)];
      E.push_back({std::min(u, v), std::max(u, v), u < v, static_cast<std::uint32_t>(f), w});
    }
  std::sort(E.begin(), E.end());
  for (std::size_t i = 0; i < E.size();) {
    std::size_t j = i + 1;
    while (j < E.size() && E[j].a == E[i].a && E[j].b == E[i].b) ++j;
    const std::string edge = "boundary edge (" + std::to_string(E[i].a) + ", " + std::to_string(E[i].b) + ")";
    if (j - i != 2)
      return fail(r, edge + " lies on " + std::to_string(j - i) + " boundary facets; expected 2 (a closed hull surface)");
    if (E[i].forward == E[i + 1].forward)
      return fail(r, edge + ": its two boundary facets are inconsistently oriented");
    for (int s = 0; s < 2; ++s) {
      const EdgeRec& e = E[i + static_cast<std::size_t>(s)];
      const EdgeRec& o = E[i + static_cast<std::size_t>(1 - s)];
      const auto& bf = boundary[e.facet];
      if (CGAL::orientation(P[bf[0]], P[bf[1]], P[bf[2]], P[o.third]) == CGAL::POSITIVE)
        return fail(r, "the boundary is not convex at " + edge + ": " + pt_str(o.third) +
                           " is outside the plane of the boundary facet (" + std::to_string(bf[0]) + ", " +
                           std::to_string(bf[1]) + ", " + std::to_string(bf[2]) + ")");
    }
    i = j;
  }
  // 5c. the literal hull test, when affordable.
  if (static_cast<double>(boundary.size()) * static_cast<double>(np) <= 2e7) {
    for (const auto& bf : boundary)
      for (std::size_t i = 0; i < np; ++i)
        if (CGAL::orientation(P[bf[0]], P[bf[1]], P[bf[2]], P[i]) == CGAL::POSITIVE)
          return fail(r, "the boundary is not the convex hull: " + pt_str(i) + " is outside boundary facet (" +
                             std::to_string(bf[0]) + ", " + std::to_string(bf[1]) + ", " + std::to_string(bf[2]) + ")");
  }
  // 6. degree: the centroid of a tet (strictly inside it, checked) is in no other.
  bool degree_checked = false;
  for (std::size_t probe = 0; probe < std::min<std::size_t>(nt, 16) && !degree_checked; ++probe) {
    const auto& c = T[probe];
    // The sum overflows near DBL_MAX: then the sum of quarters (exact there).
    auto mean = [](double a, double b, double c4, double d) {
      const double m = (a + b + c4 + d) / 4;
      return std::isfinite(m) ? m : a / 4 + b / 4 + c4 / 4 + d / 4;
    };
    const P3 q(mean(P[c[0]].x(), P[c[1]].x(), P[c[2]].x(), P[c[3]].x()),
               mean(P[c[0]].y(), P[c[1]].y(), P[c[2]].y(), P[c[3]].y()),
               mean(P[c[0]].z(), P[c[1]].z(), P[c[2]].z(), P[c[3]].z()));
    std::size_t inside = 0;
    bool generic = true;
    for (std::size_t t = 0; t < nt && generic; ++t) {
      int pos = 0, zero = 0;
      for (int f = 0; f < 4; ++f) {
        // Replace vertex f by q: positive iff q is on the tet's side of facet f.
        std::array<const P3*, 4> v{&P[T[t][0]], &P[T[t][1]], &P[T[t][2]], &P[T[t][3]]};
        v[static_cast<std::size_t>(f)] = &q;
        const CGAL::Orientation o = CGAL::orientation(*v[0], *v[1], *v[2], *v[3]);
        pos += o == CGAL::POSITIVE;
        zero += o == CGAL::COPLANAR;
      }
      if (pos == 4) ++inside;
      else if (pos + zero == 4) generic = false;  // q on this tet's boundary: try another probe
      if (t == probe && pos != 4) generic = false;  // rounding put the centroid outside its own (flat) tet
    }
    if (!generic) continue;
    if (inside != 1)
      return fail(r, "the tetrahedra cover the inside of " + tet_str(probe) + " " + std::to_string(inside) +
                         " times; expected once");
    degree_checked = true;
  }

  r.valid = true;
  r.message = "valid Delaunay tetrahedralization: " + std::to_string(np) + " points, " + std::to_string(nt) +
              " tetrahedra, " + std::to_string(interior) + " interior and " + std::to_string(boundary.size()) +
              " hull facets" + (mirrored ? " (tetrahedra negatively oriented throughout)" : "") +
              (degree_checked ? "" : " (cover degree not probed: no generic probe point)");
  return r;
}

}  // namespace pdt
