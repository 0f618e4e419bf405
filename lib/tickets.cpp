// SPDX-License-Identifier: MIT
#include "tickets.hpp"

#include <sys/mman.h>

#include <cassert>
#include <cstdlib>
#include <string>

#include "fault_injection.hpp"
#include "huge_pages.hpp"
#include "mix64.hpp"
#include "pdt/error.hpp"

namespace pdt::detail {

template <class T>
T* TicketTable::SlotAllocator<T>::allocate(std::size_t n) {
  constexpr std::size_t huge = std::size_t{2} << 20;
  const std::size_t bytes = n * sizeof(T);
  if (bytes < huge) return std::allocator<T>().allocate(n);
  const std::size_t rounded = (bytes + huge - 1) / huge * huge;
  const bool advise = huge_pages_advised();  // may throw: before the allocation
  void* p = std::aligned_alloc(huge, rounded);
  if (!p) throw std::bad_alloc();
  if (advise) ::madvise(p, rounded, MADV_HUGEPAGE);
  return static_cast<T*>(p);
}

template <class T>
void TicketTable::SlotAllocator<T>::deallocate(T* p, std::size_t n) noexcept {
  if (n * sizeof(T) < (std::size_t{2} << 20))
    std::allocator<T>().deallocate(p, n);
  else
    std::free(p);
}

template struct TicketTable::SlotAllocator<TicketTable::Slot>;

// ---------------------------------------------------------------------------
// One shard: open addressing on mix64(ticket + 1), linear probing
// ---------------------------------------------------------------------------
TicketTable::Slot* TicketTable::Shard::find(std::uint64_t t) {
  if (slots.empty()) return nullptr;
  const std::size_t mask = slots.size() - 1;
  assert(prefetch_base.load(std::memory_order_relaxed) == reinterpret_cast<std::uintptr_t>(slots.data()) &&
         prefetch_mask.load(std::memory_order_relaxed) == mask);  // prefetch() follows the slots
  for (std::size_t i = mix64(t + 1) & mask;; i = (i + 1) & mask) {
    if (slots[i].key == t + 1) return &slots[i];
    if (slots[i].key == 0) return nullptr;
  }
}

const TicketTable::Slot* TicketTable::Shard::find(std::uint64_t t) const {
  return const_cast<Shard*>(this)->find(t);
}

void TicketTable::Shard::reserve(std::size_t n) {
  std::size_t want = 16;
  while (want < 2 * n) want <<= 1;
  if (want <= slots.size()) return;
  PDT_FAULT_POINT("ticket shard");
  std::vector<Slot, SlotAllocator<Slot>> old(want);
  old.swap(slots);
  const std::size_t mask = slots.size() - 1;
  prefetch_base.store(reinterpret_cast<std::uintptr_t>(slots.data()), std::memory_order_relaxed);
  prefetch_mask.store(mask, std::memory_order_relaxed);
  for (const Slot& s : old) {
    if (s.key == 0) continue;
    std::size_t i = mix64(s.key) & mask;
    while (slots[i].key != 0) i = (i + 1) & mask;
    slots[i] = s;
  }
}

void TicketTable::Shard::insert(std::uint64_t t) {
  const std::size_t mask = slots.size() - 1;
  std::size_t i = mix64(t + 1) & mask;
  while (slots[i].key != 0) i = (i + 1) & mask;
  slots[i] = Slot{};
  slots[i].key = t + 1;
  ++count;
}

void TicketTable::Shard::erase(Slot* s) {
  const std::size_t mask = slots.size() - 1;
  std::size_t hole = static_cast<std::size_t>(s - slots.data());
  for (std::size_t i = (hole + 1) & mask; slots[i].key != 0; i = (i + 1) & mask) {
    const std::size_t home = mix64(slots[i].key) & mask;
    const bool stays = hole <= i ? (hole < home && home <= i) : (hole < home || home <= i);
    if (stays) continue;
    slots[hole] = slots[i];
    hole = i;
  }
  slots[hole] = Slot{};
  --count;
}

// ---------------------------------------------------------------------------
// The table
// ---------------------------------------------------------------------------
void TicketTable::unknown(std::uint64_t t, const char* why) {
  throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": " + why);
}

void TicketTable::prefetch(std::uint64_t t) const {
  const Shard& s = shard(t);
  const std::uintptr_t base = s.prefetch_base.load(std::memory_order_relaxed);
  if (base == 0) return;
  // Integer arithmetic: base and mask may be from two different resizes, so
  // the address may lie outside every vector (a prefetch never faults).
  const std::uintptr_t home = base + (mix64(t + 1) & s.prefetch_mask.load(std::memory_order_relaxed)) * sizeof(Slot);
  __builtin_prefetch(reinterpret_cast<const void*>(home), 1);
}

std::uint64_t TicketTable::issue(std::uint64_t n) {
  // Tickets are consecutive per call: one issuer at a time reserves room in
  // every shard it touches, then takes the numbers.
  std::lock_guard issuing(issue_mutex_);
  const std::uint64_t first = next_.load(std::memory_order_relaxed);
  const std::uint64_t per_shard = n / shard_count + 1;
  for (unsigned k = 0; k < shard_count && k < n; ++k) {
    Shard& s = shards_[(first + k) % shard_count];
    std::lock_guard lock(s.mutex);
    s.reserve(s.count + per_shard);
  }
  for (unsigned k = 0; k < shard_count && k < n; ++k) {  // shard by shard: one lock each
    Shard& s = shard(first + k);
    std::lock_guard lock(s.mutex);
    for (std::uint64_t t = first + k; t < first + n; t += shard_count) s.insert(t);
  }
  live_.fetch_add(n, std::memory_order_relaxed);
  next_.store(first + n, std::memory_order_release);
  return first;
}

TicketView TicketTable::claim_undo(std::uint64_t t, const StableArray<VertexRec>& verts) {
  if (t >= next_.load(std::memory_order_acquire)) unknown(t, "no such insertion was submitted");
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  Slot* slot = s.find(t);
  if (!slot) unknown(t, "it was already undone, or its vertex was removed meanwhile");
  if (slot->undone) unknown(t, "it was already undone");
  if (slot->state == TicketState::failed) {
    s.errors.erase(t);
    s.erase(slot);
    live_.fetch_sub(1, std::memory_order_relaxed);
    unknown(t, "that insertion failed");
  }
  if (vertex_gone(*slot, verts)) {
    s.erase(slot);
    live_.fetch_sub(1, std::memory_order_relaxed);
    unknown(t, "its vertex was removed meanwhile (by handle or id)");
  }
  slot->undone = true;
  return {slot->state, slot->vertex, slot->stamp};
}

void TicketTable::unclaim_undo(std::uint64_t t) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  if (Slot* slot = s.find(t)) slot->undone = false;
}

TicketView TicketTable::view(std::uint64_t t) const {
  const Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  const Slot* slot = s.find(t);
  if (!slot) return {TicketState::failed, no_vertex, 0};
  return {slot->state, slot->vertex, slot->stamp};
}

OpRecord* TicketTable::park(std::uint64_t t, OpRecord* undo) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  Slot* slot = s.find(t);
  if (!slot || slot->state != TicketState::pending) return undo;  // done meanwhile: run it now
  slot->parked = undo;
  return nullptr;
}

OpRecord* TicketTable::finish_inserted(std::uint64_t t, VertexId v, bool inserted, std::uint64_t stamp) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  Slot* slot = s.find(t);
  slot->state = TicketState::inserted;
  slot->vertex = v;
  slot->inserted = inserted;
  slot->stamp = stamp;
  OpRecord* undo = slot->parked;
  slot->parked = nullptr;
  return undo;
}

OpRecord* TicketTable::finish_failed(std::uint64_t t, std::exception_ptr error) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  Slot* slot = s.find(t);
  slot->state = TicketState::failed;
  OpRecord* undo = slot->parked;
  slot->parked = nullptr;
  try {
    s.errors[t] = std::move(error);
  } catch (...) {
    // No room to keep the error: insertion_result(t) will say it failed without it.
  }
  return undo;
}

void TicketTable::release(std::uint64_t t) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  if (Slot* slot = s.find(t)) {
    s.errors.erase(t);
    s.erase(slot);
    live_.fetch_sub(1, std::memory_order_relaxed);
  }
}

InsertResult TicketTable::result(std::uint64_t t, const StableArray<VertexRec>& verts) const {
  if (t >= next_.load(std::memory_order_acquire))
    throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) + " was never submitted");
  const Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  const Slot* slot = s.find(t);
  if (!slot || (!slot->undone && vertex_gone(*slot, verts)))
    throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) +
                                                 " was released: it was undone, or its vertex was removed");
  switch (slot->state) {
    case TicketState::inserted: return {slot->vertex, slot->inserted, slot->stamp};
    case TicketState::failed: {
      auto it = s.errors.find(t);
      if (it != s.errors.end()) std::rethrow_exception(it->second);
      throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) + " failed");
    }
    case TicketState::pending: break;
  }
  throw Error(ErrorCode::invalid_argument,
              "insertion " + std::to_string(t) + " has not finished; drain() first, or wait for its callback");
}

void TicketTable::sweep_if_large(const StableArray<VertexRec>& verts, std::uint64_t live_vertices) {
  const std::uint64_t live_now = live_.load(std::memory_order_relaxed);
  if (live_now < sweep_at_.load(std::memory_order_relaxed)) return;
  std::uint64_t erased = 0;
  for (Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    for (std::size_t i = 0; i < s.slots.size();) {
      Slot& slot = s.slots[i];
      // A done insertion whose vertex incarnation is gone can no longer be
      // undone by ticket (an undo claimed for it will fail on its own).
      const bool dead = slot.key != 0 && !slot.undone && vertex_gone(slot, verts);
      if (dead) {
        s.erase(&slot);  // the next entry may have shifted into i: look at i again
        ++erased;
      } else {
        ++i;
      }
    }
  }
  const std::uint64_t before = live_.fetch_sub(erased, std::memory_order_relaxed);
  // Next sweep when the table doubles past what is live now (amortised O(1)).
  // Tickets issued during the sweep may be among the erased (issue() counts
  // them in live_ after inserting them), so neither live_now - erased nor
  // before - erased is sure to be >= 0: clamp, never wrap.
  const std::uint64_t left = before > erased ? before - erased : 0;
  sweep_at_.store(2 * std::max<std::uint64_t>(left, live_vertices) + (1 << 16), std::memory_order_relaxed);
}

}  // namespace pdt::detail
