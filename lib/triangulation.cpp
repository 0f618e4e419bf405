// SPDX-License-Identifier: MIT
// pdt::Triangulation, the public face of the kernel: argument checking, then
// the kernel's operations in the sequential context, and the queries.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "pdt/error.hpp"
#include "point_checks.hpp"
#include "spatial_order.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

namespace {

using detail::KPoint;
using detail::require_finite;
using detail::to_kpoint;

// The rules every mutator checks: an attached engine owns the triangulation;
// its own change hook reports a change still being made (changing it there,
// or replacing the running hook, would pull the ground from under that call).
void require_detached(const Triangulation::Impl& m, const char* what) {
  if (m.engine.load(std::memory_order_acquire) == nullptr) {
    // Detached: the sequential context is this thread's alone (an engine's
    // global steps use it too, so with one attached in_hook is not read).
    if (m.seq && m.seq->in_hook)
      throw Error(ErrorCode::invalid_argument,
                  std::string("Triangulation::") + what +
                      " from the triangulation's own change hook: the hook reports a change still being made; note "
                      "what to do and do it after the call that made the change returns");
    return;
  }
  throw Error(ErrorCode::invalid_argument,
              std::string("Triangulation::") + what +
                  " while an Engine is attached: an engine owns its triangulation from construction to "
                  "destruction; submit through the engine, or destroy it first");
}

// The scratch of const queries: one per thread, so any number of threads may
// query at once (no lock is taken: the triangulation must be quiescent).
detail::OpContext& query_context() {
  thread_local detail::OpContext ctx(0, false);
  return ctx;
}

}  // namespace

Triangulation::Triangulation() : impl_(std::make_unique<Impl>()) {}
Triangulation::~Triangulation() {
  // An attached engine's workers and destructor still use this storage:
  // going on would corrupt memory later, far from the cause. Stop here,
  // naming the rule (a destructor cannot throw it).
  if (impl_ && impl_->engine.load(std::memory_order_acquire) != nullptr) {
    std::fputs("pdt: a Triangulation was destroyed while an Engine is attached to it; the triangulation must "
               "outlive its engine (destroy the Engine first)\n",
               stderr);
    std::abort();
  }
  if (impl_ && impl_->seq && impl_->seq->in_hook) {
    std::fputs("pdt: a Triangulation was destroyed from its own change hook, while the change it reports is "
               "being made; destroy it after that call returns\n",
               stderr);
    std::abort();
  }
}

Triangulation::Triangulation(Triangulation&& o) {
  require_detached(*o.impl_, "move");
  impl_ = std::move(o.impl_);
  o.impl_ = std::make_unique<Impl>();  // a moved-from triangulation is empty and usable
}

Triangulation& Triangulation::operator=(Triangulation&& o) {
  require_detached(*impl_, "move assignment");  // before the self check: refused however it is called
  require_detached(*o.impl_, "move assignment");
  if (this == &o) return *this;
  auto fresh = std::make_unique<Impl>();
  impl_ = std::move(o.impl_);
  o.impl_ = std::move(fresh);
  return *this;
}

// After each sequential mutator (also when it throws), the sequential context
// keeps no more scratch than OpContext::scratch_kept entries a container.
using ReleaseLargeScratchAfter = detail::OpContext::ReleaseLargeScratchAfter;

InsertResult Triangulation::insert(const Point3& p, Hint hint) {
  require_detached(*impl_, "insert");
  require_finite(p);
  Impl& m = *impl_;
  const ReleaseLargeScratchAfter release{*m.seq};
  VertexId start = hint.vertex;
  if (start == no_vertex && hint.cell != no_cell && m.cell_alive(hint.cell))
    for (int i = 0; i < 4 && start == no_vertex; ++i)
      if (m.cells[hint.cell].v[i] != 0) start = m.cells[hint.cell].v[i];
  Impl::Inserted out;
  m.insert(*m.seq, to_kpoint(p), start, out);  // single-threaded: always done
  return out.result;
}

InsertResult Triangulation::insert_if_alive(const Point3& p, CellHandle h) {
  require_detached(*impl_, "insert_if_alive");
  require_finite(p);
  Impl& m = *impl_;
  const ReleaseLargeScratchAfter release{*m.seq};
  Impl::Inserted out;
  m.insert(*m.seq, to_kpoint(p), no_vertex, out, &h);  // single-threaded: always done
  return out.result;
}

std::vector<InsertResult> Triangulation::insert_batch(std::span<const Point3> points) {
  require_detached(*impl_, "insert_batch");
  for (const Point3& p : points) require_finite(p);
  if (points.size() >= no_vertex)
    throw Error(ErrorCode::invalid_argument,
                "insert_batch: " + std::to_string(points.size()) + " points; vertex ids allow at most 2^32 - 2");
  const std::vector<std::uint32_t> order = detail::spatial_order(points, false);
  std::vector<InsertResult> out(points.size());
  Impl& m = *impl_;
  const ReleaseLargeScratchAfter release{*m.seq};  // once, after the whole batch
  // A batch at least as large as the mesh: its vertices are not noted in
  // the jump grid one by one (OpContext::large_batch), also if one throws.
  struct LargeBatch {
    detail::OpContext& ctx;
    ~LargeBatch() { ctx.large_batch = false; }
  } large_batch{*m.seq};
  m.seq->large_batch = points.size() >= static_cast<std::size_t>(m.n_vertices.load());
  VertexId previous = no_vertex;  // the walk starts at the last vertex: the order keeps it near
  // The order scatters the reads of points and the writes of out over memory
  // (a cache and TLB miss each). Gathered a chunk at a time in a loop of
  // their own, the misses overlap instead of stalling one insertion each.
  constexpr std::size_t chunk = 1024;
  std::vector<KPoint> gathered(std::min(chunk, order.size()));
  std::vector<InsertResult> made(gathered.size());
  for (std::size_t first = 0; first < order.size(); first += chunk) {
    const std::size_t count = std::min(chunk, order.size() - first);
    const std::uint32_t* ids = order.data() + first;
    for (std::size_t k = 0; k < count; ++k) gathered[k] = to_kpoint(points[ids[k]]);
    for (std::size_t k = 0; k < count; ++k) {
      Impl::Inserted r;
      m.insert(*m.seq, gathered[k], previous, r);  // single-threaded: always done
      made[k] = r.result;
      previous = r.result.vertex;
    }
    for (std::size_t k = 0; k < count; ++k) out[ids[k]] = made[k];
  }
  return out;
}

RemoveResult Triangulation::remove(VertexId v) {
  require_detached(*impl_, "remove");
  RemoveResult out = RemoveResult::removed;
  const ReleaseLargeScratchAfter release{*impl_->seq};
  impl_->remove(*impl_->seq, v, 0, out);
  return out;
}

RemoveResult Triangulation::remove(VertexHandle v) {
  require_detached(*impl_, "remove");
  if (v.incarnation == 0)
    throw Error(ErrorCode::unknown_vertex,
                "cannot remove vertex " + std::to_string(v.id) + ": the handle has no incarnation (an empty handle)");
  RemoveResult out = RemoveResult::removed;
  const ReleaseLargeScratchAfter release{*impl_->seq};
  impl_->remove(*impl_->seq, v.id, v.incarnation, out);
  return out;
}

void Triangulation::clear() {
  require_detached(*impl_, "clear");
  impl_->clear();
}

void Triangulation::shrink_to_fit() {
  require_detached(*impl_, "shrink_to_fit");
  impl_->shrink_to_fit();
}

void Triangulation::set_change_hook(ChangeHook hook, bool report_destroyed) {
  require_detached(*impl_, "set_change_hook");
  Impl& m = *impl_;
  m.hook = std::move(hook);
  m.seq->hook = m.hook ? &m.hook : nullptr;
  m.report_destroyed = report_destroyed;
  m.seq->report_destroyed = report_destroyed;
}

int Triangulation::dimension() const { return impl_->dim.load(); }
std::size_t Triangulation::number_of_vertices() const { return static_cast<std::size_t>(impl_->n_vertices.load()); }
std::size_t Triangulation::number_of_finite_cells() const {
  return static_cast<std::size_t>(impl_->n_finite_cells.load());
}
std::size_t Triangulation::number_of_cells() const { return static_cast<std::size_t>(impl_->n_cells.load()); }
bool Triangulation::is_vertex(VertexId v) const { return impl_->vertex_alive(v); }

namespace {
// The raw accessors' preconditions, refused by name rather than read past an
// array: a vertex id that is_vertex() accepts, a cell id below
// cell_id_bound() (live or free), a slot 0..3.
void require_vertex(const Triangulation::Impl& m, VertexId v, const char* what) {
  if (!m.vertex_alive(v))
    throw Error(ErrorCode::unknown_vertex, std::string("Triangulation::") + what + "(" + std::to_string(v) +
                                               "): not a live finite vertex (is_vertex(" + std::to_string(v) +
                                               ") is false); ask is_vertex first");
}
void require_cell_slot(const Triangulation::Impl& m, CellId c, int i, const char* what) {
  if (c >= m.cells.size())
    throw Error(ErrorCode::invalid_argument, std::string("Triangulation::") + what + ": cell id " + std::to_string(c) +
                                                 " is not below cell_id_bound() (" + std::to_string(m.cells.size()) +
                                                 ")");
  if (i < 0 || i > 3)
    throw Error(ErrorCode::invalid_argument, std::string("Triangulation::") + what + ": slot " + std::to_string(i) +
                                                 " of cell " + std::to_string(c) + "; a cell's slots are 0..3");
}
}  // namespace

Point3 Triangulation::point(VertexId v) const {
  require_vertex(*impl_, v, "point");
  const auto& p = impl_->pt(v);
  return {p.x(), p.y(), p.z()};
}

std::uint32_t Triangulation::multiplicity(VertexId v) const {
  return impl_->vertex_alive(v) ? impl_->verts[v].multiplicity : 0;
}

LocateResult Triangulation::locate(const Point3& p, Hint hint) const {
  require_finite(p);
  LocateResult out;
  impl_->locate(query_context(), to_kpoint(p), hint.vertex, hint.cell, out);  // not locking: always done
  return out;
}

VertexId Triangulation::nearest_vertex(const Point3& p) const {
  require_finite(p);
  VertexId out = no_vertex;
  impl_->nearest_vertex(query_context(), to_kpoint(p), out);  // not locking: always done
  return out;
}

bool Triangulation::is_vertex(VertexHandle v) const {
  return impl_->vertex_alive(v.id) && v.incarnation != 0 &&
         impl_->verts[v.id].stamp.load(std::memory_order_relaxed) == v.incarnation;
}

VertexHandle Triangulation::vertex_handle(VertexId v) const {
  return {v, impl_->vertex_alive(v) ? impl_->verts[v].stamp.load(std::memory_order_relaxed) : 0};
}

CellHandle Triangulation::cell_handle(CellId c) const {
  if (!impl_->cell_alive(c))
    throw Error(ErrorCode::invalid_argument, "Triangulation::cell_handle(" + std::to_string(c) +
                                                 "): not a live cell (is_cell(" + std::to_string(c) +
                                                 ") is false); ask is_cell first");
  return impl_->handle_of(c);
}

std::optional<CellView> Triangulation::cell(CellHandle h) const {
  bool alive = false;
  CellView view;
  impl_->find_cell(query_context(), h, &alive, &view);  // not locking: always done
  if (!alive) return std::nullopt;
  return view;
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
  detail::for_each_kept(1, m.verts.size(), m.released_ranges(), [&](std::size_t from, std::size_t to) {
    for (std::size_t v = from; v < to; ++v)
      if (m.verts[v].multiplicity > 0) out.push_back(static_cast<VertexId>(v));
  });
  return out;
}

CellId Triangulation::cell_id_bound() const { return static_cast<CellId>(impl_->cells.size()); }
bool Triangulation::is_cell(CellId c) const { return impl_->cell_alive(c); }
bool Triangulation::is_finite_cell(CellId c) const { return impl_->cell_alive(c) && !impl_->cell_infinite(c); }
VertexId Triangulation::cell_vertex(CellId c, int i) const {
  require_cell_slot(*impl_, c, i, "cell_vertex");
  return impl_->cells[c].v[i];
}
CellId Triangulation::cell_neighbor(CellId c, int i) const {
  require_cell_slot(*impl_, c, i, "cell_neighbor");
  return impl_->cells[c].n[i] >> 2;
}
VertexId Triangulation::vertex_id_bound() const { return static_cast<VertexId>(impl_->verts.size()); }

bool Triangulation::validate(std::string* why) const { return impl_->validate(why); }
const TriangulationStats& Triangulation::stats() const { return impl_->seq->stats; }

std::size_t Triangulation::memory_bytes() const {
  const Impl& m = *impl_;
  return m.cells.size() * (sizeof(detail::CellRec) + sizeof(std::uint32_t)) +  // records and tags
         (m.verts.size() - m.released_vertex_count.load(std::memory_order_relaxed)) * sizeof(detail::VertexRec) +
         m.grid.bytes();
}

}  // namespace pdt
