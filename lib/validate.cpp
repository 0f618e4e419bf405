// SPDX-License-Identifier: MIT
// Triangulation::Impl::validate: the invariants I1..I6 of triangulation_impl.hpp.
#include <algorithm>
#include <sstream>
#include <vector>

#include "triangulation_impl.hpp"

namespace pdt {

using detail::facet_vertex;

namespace {

struct Failure {
  std::ostringstream os;
  template <class T>
  Failure& operator<<(const T& x) {
    os << x;
    return *this;
  }
};

}  // namespace

bool Triangulation::Impl::validate(std::string* why) const {
  Failure f;
  auto fail = [&](Failure& msg) {
    if (why) *why = msg.os.str();
    return false;
  };
  if (!filter.check()) return fail(f << "the predicate filter's epsilons do not match its box");
  // Vertices (I4) and counts.
  std::size_t live_vertices = 0;
  const std::vector<detail::IdRange> released = released_ranges();  // all-zero records: not read
  for (std::size_t i = 0; i < released.size(); ++i) {
    const detail::IdRange r = released[i];
    if (r.first == 0 || r.first >= r.end || r.end > verts.size() || (i > 0 && released[i - 1].end > r.first))
      return fail(f << "released vertex ids [" << r.first << ", " << r.end << ") overlap or leave the ids");
  }
  std::size_t released_count = 0;
  for (const detail::IdRange r : released) released_count += r.end - r.first;
  if (released_count != released_vertex_count.load(std::memory_order_relaxed))
    return fail(f << "released vertex ids number " << released_count << ", their count says "
                  << released_vertex_count.load(std::memory_order_relaxed));
  std::vector<VertexId> live_ids;
  detail::for_each_kept(1, verts.size(), released, [&](std::size_t from, std::size_t to) {
    for (std::size_t v = from; v < to; ++v)
      if (verts[v].multiplicity > 0) live_ids.push_back(static_cast<VertexId>(v));
  });
  for (VertexId v : live_ids) {
    ++live_vertices;
    const KPoint& p = verts[v].p;
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z()))
      return fail(f << "vertex " << v << " has a non-finite coordinate");
    if (!filter.contains(p)) return fail(f << "vertex " << v << " lies outside the predicate filter's box");
    if (dim == 3) {
      CellId c = verts[v].cell;
      if (!cell_alive(c)) return fail(f << "vertex " << v << ": incident cell " << c << " is not a live cell");
      if (index_of(c, v) < 0) return fail(f << "vertex " << v << ": incident cell " << c << " does not contain it");
    }
  }
  const auto n_vertices = static_cast<std::size_t>(this->n_vertices.load());
  const auto n_cells = static_cast<std::size_t>(this->n_cells.load());
  const auto n_finite_cells = static_cast<std::size_t>(this->n_finite_cells.load());
  const int dim = this->dim.load();
  if (live_vertices != n_vertices)
    return fail(f << "vertex count " << n_vertices << " but " << live_vertices << " live vertices");

  if (dim < 3) {
    if (n_cells != 0) return fail(f << "dimension " << dim << " but " << n_cells << " cells");
    if (flat.size() != n_vertices) return fail(f << "flat list holds " << flat.size() << " of " << n_vertices);
    for (std::size_t i = 0; i < flat.size(); ++i)
      if (verts[flat[i]].cell != i) return fail(f << "flat vertex " << flat[i] << " has a wrong position");
    detail::AffineBasis spanned;
    for (VertexId v : flat)
      if (spanned.offer(v, pt(v)) && spanned.dimension() == 3)
        return fail(f << "dimension " << dim << " but vertex " << v << " is off the plane of the others");
    if (spanned.dimension() != dim)
      return fail(f << "dimension " << dim << " but the vertices span " << spanned.dimension());
    return true;
  }

  std::size_t live_cells = 0, finite_cells = 0;
  for (CellId c = 0; c < cells.size(); ++c) {
    if (!cell_alive(c)) {
      // I8
      const std::uint32_t t = tags[c].load(std::memory_order_relaxed);
      if (t != 0 && (t & mark_bits) != mark_free)
        return fail(f << "cell id " << c << " is free but its tag (incarnation " << (t >> 2) << ") does not say so");
      continue;
    }
    ++live_cells;
    const CellRec& r = cells[c];
    bool finite = true;
    // I1
    for (int i = 0; i < 4; ++i) {
      VertexId v = r.v[i];
      if (v != 0 && !vertex_alive(v)) return fail(f << "cell " << c << " holds dead vertex " << v);
      if (v == 0) finite = false;
      for (int j = i + 1; j < 4; ++j)
        if (r.v[j] == v) return fail(f << "cell " << c << " holds vertex " << v << " twice");
    }
    if (finite) ++finite_cells;
    // I2
    for (int i = 0; i < 4; ++i) {
      CellId d = r.n[i] >> 2;
      int j = static_cast<int>(r.n[i] & 3);
      if (!cell_alive(d)) return fail(f << "cell " << c << " facet " << i << ": neighbour " << d << " is not live");
      if (cells[d].n[j] != 4 * c + static_cast<std::uint32_t>(i))
        return fail(f << "cell " << c << " facet " << i << ": neighbour " << d << " does not point back");
      VertexId a[3], b[3];
      for (int t = 0; t < 3; ++t) a[t] = r.v[facet_vertex[i][t]], b[t] = cells[d].v[facet_vertex[j][t]];
      // Opposite orientation: b is a cyclic rotation of reversed a.
      bool ok = false;
      for (int s = 0; s < 3; ++s)
        if (b[s] == a[0] && b[(s + 2) % 3] == a[1] && b[(s + 1) % 3] == a[2]) ok = true;
      if (!ok) return fail(f << "cells " << c << " and " << d << " disagree on their shared facet");
    }
    // I3
    if (finite && detail::orient(pt(r.v[0]), pt(r.v[1]), pt(r.v[2]), pt(r.v[3])) <= 0)
      return fail(f << "cell " << c << " is not positively oriented");
    // I7
    if (mark(c) != 0) return fail(f << "cell " << c << " is still marked (" << mark(c) << ")");
  }
  if (live_cells != n_cells) return fail(f << "cell count " << n_cells << " but " << live_cells << " live cells");
  if (finite_cells != n_finite_cells)
    return fail(f << "finite cell count " << n_finite_cells << " but " << finite_cells << " finite cells");
  // I5: local Delaunay (and hull convexity, through the infinite cells).
  for (CellId c = 0; c < cells.size(); ++c) {
    if (!cell_alive(c)) continue;
    for (int i = 0; i < 4; ++i) {
      CellId d = cells[c].n[i] >> 2;
      VertexId opp = cells[d].v[cells[c].n[i] & 3];
      if (opp == 0) continue;
      if (in_conflict(c, pt(opp), detail::FilterEps{}))  // CGAL's predicates alone: a check of the filter too
        return fail(f << "facet " << i << " of cell " << c << " is not locally Delaunay: vertex " << opp
                      << " of neighbour " << d << " is inside its circumsphere");
    }
  }
  // Euler: for a triangulation of the 3-sphere (with the infinite vertex), V - E + F - C = 0.
  // With F = 2C: E = V + C.
  const std::size_t distinct_edges = count_distinct_edges();
  if (distinct_edges != n_vertices + 1 + n_cells)
    return fail(f << "Euler characteristic: " << n_vertices + 1 << " vertices, " << distinct_edges << " edges, "
                  << n_cells << " cells; not a triangulation of the sphere");
  return true;
}

std::size_t Triangulation::Impl::count_distinct_edges(std::size_t pass_edges) const {
  // In passes over ranges of the edges' lower vertex id, each pass's edges
  // sorted in one array (about pass_edges of them): one large block, which
  // goes back to the system when freed. (A hash set of the 7.7M edges of a
  // 1M-vertex mesh left 253 MB of small blocks in the heap, resident after
  // validate returned.)
  const std::size_t all_edges = 6 * static_cast<std::size_t>(std::max<std::int64_t>(0, n_cells.load()));
  const std::size_t id_bound = verts.size();
  const std::size_t passes = std::clamp<std::size_t>((all_edges + pass_edges - 1) / pass_edges, 1, id_bound);
  std::size_t distinct = 0;
  std::vector<std::uint64_t> edges;
  edges.reserve(std::min(all_edges, 2 * pass_edges));
  for (std::size_t pass = 0; pass < passes; ++pass) {
    const std::size_t lo = id_bound * pass / passes, hi = id_bound * (pass + 1) / passes;
    edges.clear();
    for (CellId c = 0; c < cells.size(); ++c) {
      if (!cell_alive(c)) continue;
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
          VertexId a = cells[c].v[i], b = cells[c].v[j];
          if (a > b) std::swap(a, b);
          if (a >= lo && a < hi) edges.push_back((std::uint64_t{a} << 32) | b);
        }
    }
    std::sort(edges.begin(), edges.end());
    distinct += static_cast<std::size_t>(std::unique(edges.begin(), edges.end()) - edges.begin());
  }
  return distinct;
}

}  // namespace pdt
