// pdt::Triangulation, the public face of the kernel: argument checking, then
// the kernel's operations in the sequential context, and the queries.
#include <string>

#include "pdt/error.hpp"
#include "point_checks.hpp"
#include "spatial_order.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

namespace {

using detail::require_finite;
using detail::to_kpoint;

}  // namespace

Triangulation::Triangulation() : impl_(std::make_unique<Impl>()) {}
Triangulation::~Triangulation() = default;
Triangulation::Triangulation(Triangulation&&) noexcept = default;
Triangulation& Triangulation::operator=(Triangulation&&) noexcept = default;

InsertResult Triangulation::insert(const Point3& p, Hint hint) {
  require_finite(p);
  Impl& m = *impl_;
  VertexId start = hint.vertex;
  if (start == no_vertex && hint.cell != no_cell && m.cell_alive(hint.cell))
    for (int i = 0; i < 4 && start == no_vertex; ++i)
      if (m.cells[hint.cell].v[i] != 0) start = m.cells[hint.cell].v[i];
  Impl::Inserted out;
  m.insert(*m.seq, to_kpoint(p), start, out);  // single-threaded: always done
  return out.result;
}

std::vector<InsertResult> Triangulation::insert_batch(std::span<const Point3> points) {
  for (const Point3& p : points) require_finite(p);
  if (points.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument,
                "insert_batch: " + std::to_string(points.size()) + " points; vertex ids allow at most 2^32 - 2");
  const std::vector<std::uint32_t> order = detail::spatial_order(points, false);
  std::vector<InsertResult> out(points.size());
  Impl& m = *impl_;
  VertexId previous = no_vertex;  // the walk starts at the last vertex: the order keeps it near
  for (std::uint32_t i : order) {
    Impl::Inserted r;
    m.insert(*m.seq, to_kpoint(points[i]), previous, r);  // single-threaded: always done
    out[i] = r.result;
    previous = r.result.vertex;
  }
  return out;
}

RemoveResult Triangulation::remove(VertexId v) {
  RemoveResult out = RemoveResult::removed;
  impl_->remove(*impl_->seq, v, 0, out);
  return out;
}

void Triangulation::clear() { impl_->clear(); }

int Triangulation::dimension() const { return impl_->dim.load(); }
std::size_t Triangulation::number_of_vertices() const { return static_cast<std::size_t>(impl_->n_vertices.load()); }
std::size_t Triangulation::number_of_finite_cells() const {
  return static_cast<std::size_t>(impl_->n_finite_cells.load());
}
std::size_t Triangulation::number_of_cells() const { return static_cast<std::size_t>(impl_->n_cells.load()); }
bool Triangulation::is_vertex(VertexId v) const { return impl_->vertex_alive(v); }

Point3 Triangulation::point(VertexId v) const {
  const auto& p = impl_->pt(v);
  return {p.x(), p.y(), p.z()};
}

std::uint32_t Triangulation::multiplicity(VertexId v) const {
  return impl_->vertex_alive(v) ? impl_->verts[v].multiplicity : 0;
}

LocateResult Triangulation::locate(const Point3& p, Hint hint) const {
  require_finite(p);
  const Impl& m = *impl_;
  LocateResult out;
  if (m.dim < 3) {
    VertexId w = m.find_flat(to_kpoint(p));
    if (w != no_vertex) out.vertex = w, out.kind = LocateKind::on_vertex;
    return out;
  }
  detail::KPoint q = to_kpoint(p);
  detail::OpContext& ctx = *m.seq;
  VertexId s = m.start_vertex(ctx, q, hint.vertex);
  CellId start = hint.cell != no_cell && m.cell_alive(hint.cell) ? hint.cell : m.verts[s].cell;
  if (int k = m.index_of(start, 0); k >= 0) start = m.cells[start].n[k] >> 2;
  bool outside = false;
  CellId c = m.walk(ctx, q, start, &outside);
  out.cell = c;
  if (outside) {
    out.kind = LocateKind::outside_hull;
    return out;
  }
  const auto& cr = m.cells[c];
  int zeros = 0;
  for (int i = 0; i < 4; ++i) {
    const detail::KPoint* a[4] = {&m.pt(cr.v[0]), &m.pt(cr.v[1]), &m.pt(cr.v[2]), &m.pt(cr.v[3])};
    a[i] = &q;
    if (detail::orient(*a[0], *a[1], *a[2], *a[3]) == 0) ++zeros;
    if (m.pt(cr.v[i]) == q) out.vertex = cr.v[i];
  }
  out.kind = zeros == 0 ? LocateKind::in_cell : zeros == 1 ? LocateKind::on_facet
           : zeros == 2 ? LocateKind::on_edge : LocateKind::on_vertex;
  return out;
}

VertexId Triangulation::nearest_vertex(const Point3& p) const {
  require_finite(p);
  const Impl& m = *impl_;
  detail::KPoint q = to_kpoint(p);
  auto closer = [&](VertexId a, VertexId b) {  // a strictly closer to q than b
    return b == no_vertex || CGAL::compare_distance_to_point(q, m.pt(a), m.pt(b)) == CGAL::SMALLER;
  };
  VertexId best = no_vertex;
  if (m.dim < 3) {
    for (VertexId w : m.flat)
      if (closer(w, best)) best = w;
    return best;
  }
  detail::OpContext& ctx = *m.seq;
  bool outside = false;
  CellId c = m.walk(ctx, q, m.finite_cell_of(m.start_vertex(ctx, q, no_vertex)), &outside);
  for (int i = 0; i < 4; ++i) {
    VertexId w = m.cells[c].v[i];
    if (w != 0 && closer(w, best)) best = w;
  }
  // Greedy descent on the Delaunay graph ends at the nearest vertex: a vertex
  // with no strictly closer neighbour is a nearest one (its Voronoi cell holds q).
  std::vector<CellId> star;
  Impl& mm = const_cast<Impl&>(m);
  while (true) {
    mm.collect_star(ctx, best, star);
    VertexId next = best;
    for (CellId sc : star)
      for (int i = 0; i < 4; ++i) {
        VertexId w = m.cells[sc].v[i];
        if (w != 0 && closer(w, next)) next = w;
      }
    if (next == best) return best;
    best = next;
  }
}

std::vector<std::array<VertexId, 4>> Triangulation::finite_cells() const {
  const Impl& m = *impl_;
  std::vector<std::array<VertexId, 4>> out;
  out.reserve(static_cast<std::size_t>(m.n_finite_cells.load()));
  for (CellId c = 0; c < m.cells.size(); ++c) {
    if (!m.cell_alive(c) || m.cell_infinite(c)) continue;
    const auto& v = m.cells[c].v;
    out.push_back({v[0], v[1], v[2], v[3]});
  }
  return out;
}

std::vector<VertexId> Triangulation::vertices() const {
  const Impl& m = *impl_;
  std::vector<VertexId> out;
  out.reserve(static_cast<std::size_t>(m.n_vertices.load()));
  for (VertexId v = 1; v < m.verts.size(); ++v)
    if (m.verts[v].multiplicity > 0) out.push_back(v);
  return out;
}

CellId Triangulation::cell_id_bound() const { return static_cast<CellId>(impl_->cells.size()); }
bool Triangulation::is_cell(CellId c) const { return impl_->cell_alive(c); }
bool Triangulation::is_finite_cell(CellId c) const { return impl_->cell_alive(c) && !impl_->cell_infinite(c); }
VertexId Triangulation::cell_vertex(CellId c, int i) const { return impl_->cells[c].v[i]; }
CellId Triangulation::cell_neighbor(CellId c, int i) const { return impl_->cells[c].n[i] >> 2; }
VertexId Triangulation::vertex_id_bound() const { return static_cast<VertexId>(impl_->verts.size()); }

bool Triangulation::validate(std::string* why) const { return impl_->validate(why); }
const TriangulationStats& Triangulation::stats() const { return impl_->seq->stats; }

std::size_t Triangulation::memory_bytes() const {
  const Impl& m = *impl_;
  return m.cells.size() * (sizeof(detail::CellRec) + sizeof(std::uint32_t)) +
         m.verts.size() * sizeof(detail::VertexRec) + m.grid.slot_count * sizeof(VertexId);
}

}  // namespace pdt
