// SPDX-License-Identifier: MIT
// Running one operation on a worker: its kernel call under try-locks, what a
// rollback, a parked undo, an escalation or a dimension change do, and
// delivering its result.
#include <cassert>
#include <limits>
#include <utility>

#include "engine_state.hpp"
#include "pdt/error.hpp"

namespace pdt::detail {


namespace {
// Where an insertion's ticket slot is.
TicketPosition ticket_position(const OpRecord& op) { return {op.ticket_range, op.ticket_slot}; }
}  // namespace

// ---------------------------------------------------------------------------
// The kernel call
// ---------------------------------------------------------------------------
OpStatus EngineState::run_op(Worker& w, OpContext& ctx, OpRecord& op, OpResult& r, std::uint64_t& stamp) {
  struct Inside {  // ops_on_this_thread: the hook and the visitor run in here
    Inside() { ++ops_on_this_thread; }
    ~Inside() { --ops_on_this_thread; }
  } inside;
  switch (op.kind) {
    case OpKind::insert: {
      // finish_inserted's slot, fetched meanwhile (a large batch's slots are
      // written in order: the hardware fetches those ahead).
      if (!op.only_if_alive && !op.from_batch) TicketTable::prefetch(ticket_position(op));
      const VertexId hint = op.from_batch ? w.last_inserted : no_vertex;
      Triangulation::Impl::Inserted out;
      const OpStatus s = impl.insert(ctx, to_kpoint(op.point), hint, out, op.only_if_alive ? &op.cell : nullptr);
      if (s == OpStatus::done) {
        r.insert = out.result;
        stamp = out.stamp;
        if (out.result.vertex != no_vertex) w.last_inserted = out.result.vertex;
      }
      return s;
    }
    case OpKind::remove:
      return impl.remove(ctx, op.vertex, op.stamp, r.remove);
    case OpKind::remove_insertion: {
      const TicketView t = tickets.view(op.ticket);
      if (t.state != TicketState::inserted)
        throw Error(ErrorCode::unknown_vertex,
                    "cannot undo insertion " + std::to_string(op.ticket) + ": that insertion failed");
      try {
        return impl.remove(ctx, t.vertex, t.stamp, r.remove);
      } catch (const Error& e) {
        if (e.code() != ErrorCode::unknown_vertex) throw;
        throw Error(ErrorCode::unknown_vertex,
                    "cannot undo insertion " + std::to_string(op.ticket) + " (vertex " + std::to_string(t.vertex) +
                        "): its vertex was removed meanwhile (by handle or id)");
      }
    }
    case OpKind::locate:
      return impl.locate(ctx, to_kpoint(op.point), no_vertex, no_cell, r.locate);
    case OpKind::nearest_vertex:
      return impl.nearest_vertex(ctx, to_kpoint(op.point), r.nearest);
    case OpKind::visit: {
      // The visitor runs while the anchor is held; what it throws is the
      // client's, not the operation's.
      const CellVisitor guarded = [&](const CellView& view) {
        if (op.visitor) run_client([&] { op.visitor(view); });
      };
      return impl.find_cell(ctx, op.cell, &r.alive, nullptr, &guarded);
    }
  }
  return OpStatus::done;
}

// ---------------------------------------------------------------------------
// One attempt
// ---------------------------------------------------------------------------
EngineState::Outcome EngineState::execute(Worker& w, OpRecord* opp) {
  OpRecord& op = *opp;
  if (!op.routed) {
    // Submitted while its vertex was held, so its place was unknown: read it
    // now and move the operation to its block.
    const VertexId v = op.kind == OpKind::visit ? op.cell.anchor : op.vertex;
    Point3 p;
    std::uint64_t stamp = 0;
    if (v < impl.verts.size() && try_read_vertex(impl, v, 0, &p, &stamp)) {
      op.point = p;
      op.routed = true;
      Block& dest = blocks[partition.block_of(p)];
      if (dest.holder.load(std::memory_order_relaxed) != static_cast<int>(w.index)) {
        enqueue(dest, opp);
        return Outcome::parked;
      }
    } else {
      // Held again, or not a live vertex: run it here. Its block only matters
      // for locality; the kernel call rolls back (and escalates) or fails cleanly.
      op.routed = true;
    }
  }
  if (op.kind == OpKind::remove_insertion && tickets.view(op.ticket).state == TicketState::pending) {
    // The insertion it undoes is not done yet: park it on the ticket; the
    // insertion's completion re-queues it. Not an attempt, not a conflict.
    w.deferred.fetch_add(1, std::memory_order_relaxed);
    if (!tickets.park(op.ticket, opp)) return Outcome::parked;
    // Done meanwhile: run it now.
  }
  if (!world.enter(w.index)) return Outcome::global;  // stopped: wait, then retry
  OpContext& ctx = *w.ctx;
  const OpContext::ReleaseLargeScratchAfter release{ctx};  // however this attempt ends: its scratch is dead then
  OpResult r;
  OpStatus s = OpStatus::done;
  std::uint64_t stamp = 0;
  try {
    s = run_op(w, ctx, op, r, stamp);
  } catch (...) {
    impl.release_all(ctx);
    r.error = std::current_exception();
    s = OpStatus::done;
  }
  world.leave(w.index);
  switch (s) {
    case OpStatus::rollback:
      w.attempts.fetch_add(1, std::memory_order_relaxed);
      w.rollbacks.fetch_add(1, std::memory_order_relaxed);
      w.contention.attempted();
      // Counted whether or not escalation is on: OpResult::rollbacks reports it.
      if (op.rollbacks != std::numeric_limits<std::uint32_t>::max()) ++op.rollbacks;
      if (opts.escalate_after && op.rollbacks >= opts.escalate_after && run_global(w, opp, true)) {
        w.escalated.fetch_add(1, std::memory_order_relaxed);
        return Outcome::done;
      }
      return Outcome::rollback;
    case OpStatus::needs_global:
      return run_global(w, opp) ? Outcome::done : Outcome::global;
    case OpStatus::done:
      break;
  }
  w.attempts.fetch_add(1, std::memory_order_relaxed);
  w.contention.attempted();
  w.contention.completed();
  complete(w, opp, r, stamp);
  return Outcome::done;
}

bool EngineState::run_global(Worker& w, OpRecord* opp, bool escalated) {
  std::unique_lock<std::mutex> lock;
  if (!world.try_stop(w.index, lock)) return false;
  // Nobody else is inside an operation: run it single-threaded, in the
  // sequential context. Whatever happens, the world restarts.
  OpResult r;
  r.escalated = escalated;
  std::uint64_t stamp = 0;
  // What it does counts as this worker's: the sequential context's stats are
  // the triangulation's own (Triangulation::stats), which the workers' join
  // only when the engine goes.
  std::swap(impl.seq->stats, w.ctx->stats);
  try {
    run_op(w, *impl.seq, *opp, r, stamp);  // single-threaded: always done
  } catch (...) {
    r.error = std::current_exception();
  }
  std::swap(impl.seq->stats, w.ctx->stats);
  impl.seq->release_large_scratch();  // while the world is still stopped: the context is ours
  try {
    ensure_grid(true);
  } catch (const std::bad_alloc&) {
    // No new grid: walks start from the old one (or from vertices).
  }
  global_ops.fetch_add(1, std::memory_order_relaxed);
  world.restart(lock, [this](std::coroutine_handle<> h) { spawn(h); });
  w.attempts.fetch_add(1, std::memory_order_relaxed);
  w.contention.attempted();
  w.contention.completed();
  complete(w, opp, r, stamp);
  return true;
}

// ---------------------------------------------------------------------------
// Delivering the result
// ---------------------------------------------------------------------------
void EngineState::complete(Worker& w, OpRecord* opp, OpResult& r, std::uint64_t stamp) {
  OpRecord& op = *opp;
  r.kind = op.kind;
  r.rollbacks = op.rollbacks;
  if ((op.kind == OpKind::insert && !op.only_if_alive) || op.kind == OpKind::remove_insertion) r.ticket = op.ticket;
  if (op.kind == OpKind::insert && !op.only_if_alive) {
    const TicketPosition at = ticket_position(op);
    OpRecord* undo = r.error ? tickets.finish_failed(op.ticket, r.error, at)
                             : tickets.finish_inserted(op.ticket, r.insert.vertex, r.insert.inserted, stamp, at);
    if (undo) {
      undo->point = op.point;  // now known: where the vertex is
      undo->routed = true;
      enqueue(blocks[partition.block_of(op.point)], undo);
    }
  } else if (op.kind == OpKind::remove_insertion) {
    tickets.release(op.ticket);
  }
  w.completed.fetch_add(1, std::memory_order_relaxed);
  if (op.done) run_client([&] { op.done(r); });
  if (BatchCallback* batch_done = op.batch_done) {
    if (batch_done->fn) run_client([&] { batch_done->fn(r); });
    if (batch_done != w.batch_done_unpublished) {
      publish_batch_done(w);
      w.batch_done_unpublished = batch_done;
    }
    ++w.batch_done_count;  // published at the end of the claim
  }
  if (OpAwaitBase* a = op.awaiter) {
    a->result = std::move(r);
    std::coroutine_handle<> h = a->waiter;  // `a` may be gone once h resumes
    spawn(h);
  }
  if (w.kept_count < Worker::kept_max) {  // for this worker's next run point
    OpRecordPool::reset(opp);
    opp->next.store(w.kept, std::memory_order_relaxed);
    w.kept = opp;
    ++w.kept_count;
  } else {
    records.release(opp);
  }
  w.finished.store(w.finished.load(std::memory_order_relaxed) + 1, std::memory_order_release);
}

void EngineState::publish_batch_done(Worker& w) {
  BatchCallback* batch = w.batch_done_unpublished;
  if (!batch) return;
  assert(w.batch_done_count > 0);
  if (batch->remaining.fetch_sub(w.batch_done_count, std::memory_order_acq_rel) == w.batch_done_count) delete batch;
  w.batch_done_unpublished = nullptr;
  w.batch_done_count = 0;
}

}  // namespace pdt::detail
