// SPDX-License-Identifier: MIT
// Per-vertex try-locks (paper §3.2). One atomic word per vertex:
//   0          free
//   k > 0      held shared by k readers
//   -(owner)   held exclusively by the context whose id is owner
// A context records what it holds (held_shared, held_exclusive) so that it
// can release everything at once, on success or on a rollback. With a
// non-locking context (the sequential triangulation), or one that is alone
// (OpContext::alone: an engine's only worker), every call succeeds at once.
// The infinite vertex is never locked. Room in the record is made before the
// lock word changes, so a failed allocation never leaves a lock nobody holds.
#include <algorithm>
#include <cassert>
#include <thread>

#include "fault_injection.hpp"
#include "triangulation_impl.hpp"

namespace pdt {

using detail::OpContext;

bool Triangulation::Impl::lock_shared_word(OpContext& ctx, VertexId v) {
  assert(ctx.locking && !ctx.alone && v != 0);
  std::atomic<std::int32_t>& w = verts[v].lock;
  std::int32_t cur = w.load(std::memory_order_relaxed);
  if (cur == -static_cast<std::int32_t>(ctx.id)) return true;
  if (cur < 0) return false;  // another context's
  // Our own shares count in the word: with none there, we hold none (our
  // own increments are visible to us), and the list need not be searched.
  if (cur > 0)
    for (VertexId h : ctx.held_shared)
      if (h == v) return true;
  if (ctx.held_shared.size() == ctx.held_shared.capacity()) {
    PDT_FAULT_POINT("lock record");
    ctx.held_shared.reserve(2 * ctx.held_shared.capacity() + 16);
  }
  while (cur >= 0)
    if (w.compare_exchange_weak(cur, cur + 1, std::memory_order_acquire, std::memory_order_relaxed)) {
      ctx.held_shared.push_back(v);
      return true;
    }
  return false;
}

bool Triangulation::Impl::lock_exclusive_word(OpContext& ctx, VertexId v) {
  assert(ctx.locking && !ctx.alone && v != 0);
  std::atomic<std::int32_t>& w = verts[v].lock;
  const std::int32_t mine = -static_cast<std::int32_t>(ctx.id);
  std::int32_t cur = w.load(std::memory_order_relaxed);
  if (cur == mine) return true;
  if (cur < 0 || cur > 1) return false;  // another's, or another reader's (perhaps beside us)
  if (ctx.held_exclusive.size() == ctx.held_exclusive.capacity()) {
    PDT_FAULT_POINT("lock record");
    ctx.held_exclusive.reserve(2 * ctx.held_exclusive.capacity() + 16);
  }
  // An upgrade when the one reader is us (searched only when there is one:
  // with the word at 0 we hold no share).
  auto it = cur == 1 ? std::find(ctx.held_shared.begin(), ctx.held_shared.end(), v) : ctx.held_shared.end();
  if (cur == 1 && it == ctx.held_shared.end()) return false;
  std::int32_t expect = cur;
  if (!w.compare_exchange_strong(expect, mine, std::memory_order_acquire, std::memory_order_relaxed)) return false;
  if (it != ctx.held_shared.end()) {
    *it = ctx.held_shared.back();
    ctx.held_shared.pop_back();
  }
  ctx.held_exclusive.push_back(v);
  return true;
}

bool Triangulation::Impl::lock_cell_exclusive(OpContext& ctx, CellId c) {
  const VertexId* v = cells[c].v;
  return lock_exclusive(ctx, v[0]) && lock_exclusive(ctx, v[1]) && lock_exclusive(ctx, v[2]) &&
         lock_exclusive(ctx, v[3]);
}

void Triangulation::Impl::VertexWrite::take(std::atomic<std::int32_t>& word, const OpContext& ctx) {
  assert(!ctx.locking || ctx.alone);
  // No operation runs beside a global step, or beside a context that is
  // alone, so the word is 0 or held shared by readers that let go within a
  // few loads. (Held exclusively it can only
  // be by a context outside any operation, as a test does to force an
  // escalation; no reader reads it then either, so it is written as it is.)
  const std::int32_t mine = -static_cast<std::int32_t>(ctx.id);
  std::int32_t cur = word.load(std::memory_order_relaxed);
  for (unsigned spins = 0; cur >= 0; ++spins) {
    if (cur == 0 && word.compare_exchange_weak(cur, mine, std::memory_order_acquire, std::memory_order_relaxed)) {
      word_ = &word;
      return;
    }
    if (spins >= 64) std::this_thread::yield();
    cur = word.load(std::memory_order_relaxed);
  }
}

void Triangulation::Impl::release_all(OpContext& ctx) {
  for (VertexId v : ctx.held_exclusive) verts[v].lock.store(0, std::memory_order_release);
  for (VertexId v : ctx.held_shared) verts[v].lock.fetch_sub(1, std::memory_order_release);
  ctx.held_exclusive.clear();
  ctx.held_shared.clear();
}

}  // namespace pdt
