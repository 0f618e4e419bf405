// SPDX-License-Identifier: MIT
// Change reporting (changes.hpp): the cells an operation made and deleted,
// handed to the hook while the operation still holds them; and cell handles.
#include "fault_injection.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::OpContext;

CellHandle Triangulation::Impl::handle_of(CellId c) const {
  const VertexId* v = cells[c].v;
  return {c, incarnation(c), v[0] != 0 ? v[0] : v[1], mesh_id};
}

void Triangulation::Impl::fill_view(CellId c, CellView& out) const {
  out.handle = handle_of(c);
  for (int i = 0; i < 4; ++i) {
    const VertexId w = cells[c].v[i];
    out.vertices[i] = w;
    out.points[i] = w == 0 ? Point3{} : Point3{pt(w).x(), pt(w).y(), pt(w).z()};
  }
}

void Triangulation::Impl::begin_report(OpContext& ctx, std::size_t cells_made, std::size_t cells_unmade) {
  ctx.recording = ctx.hook != nullptr && *ctx.hook;
  if (!ctx.recording) return;
  ctx.created.clear();
  ctx.destroyed.clear();
  PDT_FAULT_POINT("change report");
  ctx.created.reserve(cells_made);
  ctx.views.reserve(cells_made);
  if (ctx.report_destroyed) ctx.destroyed.reserve(cells_unmade);
}

void Triangulation::Impl::end_report(OpContext& ctx, OpKind kind, VertexId v, std::uint64_t incarnation) {
  if (!ctx.recording) return;
  ctx.recording = false;
  // A sequential hook may query its triangulation, whose change is complete
  // now: its counts must say so too (an engine's hook may not: other
  // operations run meanwhile, and workers fold their counts later).
  if (!ctx.locking) fold_counters(ctx);
  ctx.views.resize(ctx.created.size());
  for (std::size_t i = 0; i < ctx.created.size(); ++i) fill_view(ctx.created[i], ctx.views[i]);
  Changes changes;
  changes.kind = kind;
  changes.vertex = {v, incarnation};
  changes.created = ctx.views;
  changes.destroyed = ctx.destroyed;
  struct Running {  // cleared also when the hook throws
    bool& flag;
    ~Running() { flag = false; }
  } running{ctx.in_hook};
  ctx.in_hook = true;
  (*ctx.hook)(changes);
}

void Triangulation::Impl::finish_change(OpContext& ctx, OpKind kind, VertexId v, std::uint64_t incarnation) {
  try {
    end_report(ctx, kind, v, incarnation);
  } catch (...) {
    release_all(ctx);
    end_op_counters(ctx);
    throw;
  }
  release_all(ctx);
  end_op_counters(ctx);
}

}  // namespace pdt
