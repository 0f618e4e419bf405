// SPDX-License-Identifier: MIT
#include "tickets.hpp"

#include <sys/mman.h>

#include <algorithm>
#include <cassert>
#include <cstdlib>
#include <string>

#include "fault_injection.hpp"
#include "for_range.hpp"
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
// One shard: open addressing, linear probing from a key's home slot
// ---------------------------------------------------------------------------
namespace {
// A key's (ticket + 1's) home slot; mask + 1 (a power of two) is at least
// 16. A shard holds every shard_count-th ticket, so k numbers its tickets in
// issue order; four consecutive ones share an aligned group of four slots
// (128 bytes) at a hashed place. A submitter issuing tickets in order then
// writes each group's lines four times instead of one random line (a cache
// and TLB miss) per ticket, and the groups' hashing keeps probe runs short
// for any pattern of live tickets.
std::size_t home_slot(std::uint64_t key, std::size_t mask) {
  const std::uint64_t k = (key - 1) / ticket_shards;
  return static_cast<std::size_t>((mix64(k >> 2) << 2) | (k & 3)) & mask;
}
}  // namespace

TicketTable::Slot* TicketTable::Shard::find(std::uint64_t t) {
  if (slots.empty()) return nullptr;
  const std::size_t mask = slots.size() - 1;
  for (std::size_t i = home_slot(t + 1, mask);; i = (i + 1) & mask) {
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
  for (const Slot& s : old) {
    if (s.key == 0) continue;
    std::size_t i = home_slot(s.key, mask);
    while (slots[i].key != 0) i = (i + 1) & mask;
    slots[i] = s;
  }
}

void TicketTable::Shard::insert(std::uint64_t t) {
  const std::size_t mask = slots.size() - 1;
  std::size_t i = home_slot(t + 1, mask);
  while (slots[i].key != 0) i = (i + 1) & mask;
  slots[i] = Slot{};
  slots[i].key = t + 1;
  ++count;
}

void TicketTable::Shard::erase(Slot* s) {
  const std::size_t mask = slots.size() - 1;
  std::size_t hole = static_cast<std::size_t>(s - slots.data());
  for (std::size_t i = (hole + 1) & mask; slots[i].key != 0; i = (i + 1) & mask) {
    const std::size_t home = home_slot(slots[i].key, mask);
    const bool stays = hole <= i ? (hole < home && home <= i) : (hole < home || home <= i);
    if (stays) continue;
    slots[hole] = slots[i];
    hole = i;
  }
  slots[hole] = Slot{};
  --count;
}

// ---------------------------------------------------------------------------
// The table: where a ticket's slot is
// ---------------------------------------------------------------------------
TicketTable::~TicketTable() {  // open_ is among ranges_
  for (TicketRange* r : ranges_) delete r;
}

TicketRange* TicketTable::range_of(std::uint64_t t) const {
  // The last range starting at or before t, if t is in it.
  auto it = std::upper_bound(ranges_.begin(), ranges_.end(), t,
                             [](std::uint64_t x, const TicketRange* r) { return x < r->first; });
  if (it == ranges_.begin()) return nullptr;
  TicketRange* r = *(it - 1);
  return t - r->first < r->n ? r : nullptr;
}

TicketTable::Slot* TicketTable::find(std::uint64_t t, TicketPosition at, TicketRange** range) {
  if (at.range) {
    assert(at.k < at.range->n && at.range->slots[at.k].key == t + 1 && range_of(t) == at.range);
    if (range) *range = at.range;
    return &at.range->slots[at.k];
  }
  if (TicketRange* r = range_of(t)) {
    if (range) *range = r;
    Slot& slot = r->slots[r->slot_of(t)];
    return slot.key == t + 1 ? &slot : nullptr;
  }
  return shard(t).find(t);
}

namespace {
// A count written only under one mutex (the shard's), read without it.
void decrement(std::atomic<std::uint32_t>& count) {
  count.store(count.load(std::memory_order_relaxed) - 1, std::memory_order_relaxed);
}
}  // namespace

std::uint64_t TicketTable::erase(std::uint64_t t, Slot* slot) {
  live_.fetch_sub(1, std::memory_order_relaxed);
  TicketRange* r = range_of(t);
  if (!r) {
    shard(t).erase(slot);
    return no_range;
  }
  *slot = Slot{};
  decrement(r->counts[t % shard_count].live);
  return r->mostly_released() ? r->first : no_range;
}

std::array<std::unique_lock<std::mutex>, TicketTable::shard_count> TicketTable::lock_all_shards() const {
  std::array<std::unique_lock<std::mutex>, shard_count> locks;
  for (unsigned j = 0; j < shard_count; ++j) locks[j] = std::unique_lock(shards_[j].mutex);
  return locks;
}

void TicketTable::compact(std::uint64_t first) {
  if (first == no_range) return;
  std::lock_guard issuing(issue_mutex_);
  auto locks = lock_all_shards();
  TicketRange* r = range_of(first);
  if (!r || r->first != first || !r->mostly_released()) return;  // gone, or no longer worth it
  assert(r != open_);  // the open range's tickets not given out count as pending
  std::size_t per_shard[shard_count] = {};
  for (std::uint32_t k = 0; k < r->n; ++k)
    if (const std::uint64_t key = r->slots[k].key) ++per_shard[(key - 1) % shard_count];
#ifndef NDEBUG
  // The counts are exact with every shard mutex held: one live per slot with a key.
  for (unsigned j = 0; j < shard_count; ++j) assert(per_shard[j] == r->counts[j].live.load(std::memory_order_relaxed));
#endif
  try {
    for (unsigned j = 0; j < shard_count; ++j) shards_[j].reserve(shards_[j].count + per_shard[j]);
  } catch (const std::bad_alloc&) {
    return;  // the range stays, and serves as before
  }
  // Nothing below fails: the shards have room, and erasing from a vector
  // does not allocate.
  for (std::uint32_t k = 0; k < r->n; ++k) {
    const Slot& slot = r->slots[k];
    if (slot.key == 0) continue;
    Shard& s = shard(slot.key - 1);
    s.insert(slot.key - 1);
    *s.find(slot.key - 1) = slot;
  }
  ranges_.erase(std::find(ranges_.begin(), ranges_.end(), r));
  for (auto& lock : locks) lock.unlock();
  delete r;
}

std::size_t TicketTable::ranged() const {
  std::lock_guard issuing(issue_mutex_);
  std::lock_guard lock(shards_[0].mutex);
  std::size_t n = 0;
  for (const TicketRange* r : ranges_) n += r == open_ ? next_.load(std::memory_order_relaxed) - r->first : r->n;
  return n;
}

std::size_t TicketTable::slots_allocated() const {
  const auto locks = lock_all_shards();
  std::size_t n = 0;
  for (const TicketRange* r : ranges_) n += r->capacity;
  for (const Shard& s : shards_) n += s.slots.size();
  return n;
}

// ---------------------------------------------------------------------------
// The table
// ---------------------------------------------------------------------------
void TicketTable::unknown(std::uint64_t t, const char* why) {
  throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": " + why);
}

std::unique_ptr<TicketRange> TicketTable::make_range(std::uint64_t first, std::uint32_t n,
                                                     const std::uint32_t* order, bool parallel) {
  PDT_FAULT_POINT("ticket range");
  auto r = std::make_unique<TicketRange>();
  r->first = first;
  r->n = r->capacity = n;
  r->slots = make_raw_array<Slot>(n);
  if (order) {
    r->position = std::make_unique_for_overwrite<std::uint32_t[]>(n);
    for_range(n, parallel, [&, slots = r->slots.get(), position = r->position.get()](std::size_t begin,
                                                                                     std::size_t end) {
      for (std::size_t k = begin; k < end; ++k) {
        slots[k] = Slot{};
        slots[k].key = first + order[k] + 1;
        position[order[k]] = static_cast<std::uint32_t>(k);
      }
    });
  } else {
    for (std::uint32_t k = 0; k < n; ++k) {
      r->slots[k] = Slot{};
      r->slots[k].key = first + k + 1;
    }
  }
  for (unsigned j = 0; j < shard_count; ++j) {  // how many t in [first, first + n) have t % 16 == j
    const std::uint64_t from = first + (j + shard_count - first % shard_count) % shard_count;
    const auto count = static_cast<std::uint32_t>(from < first + n ? (first + n - from + shard_count - 1) / shard_count : 0);
    r->counts[j].live.store(count, std::memory_order_relaxed);
    r->counts[j].pending.store(count, std::memory_order_relaxed);
  }
  assert(r->live_now() == n);
  return r;
}

std::uint64_t TicketTable::close_open_range() {
  TicketRange* r = open_;
  if (!r) return no_range;
  assert(r == ranges_.back());
  open_ = nullptr;
  open_size_ = open_range_min;
  const auto issued = static_cast<std::uint32_t>(next_.load(std::memory_order_relaxed) - r->first);
  for (std::uint32_t k = issued; k < r->n; ++k) {  // never given out: neither live nor pending
    const std::uint64_t t = r->first + k;
    decrement(r->counts[t % shard_count].live);
    decrement(r->counts[t % shard_count].pending);
    r->slots[k] = Slot{};
  }
  assert(issued > 0);  // made by issue(), which gave out its first tickets at once
  r->n = issued;
  return r->mostly_released() ? r->first : no_range;
}

std::uint64_t TicketTable::add_range(std::unique_ptr<TicketRange> r) {
  const auto locks = lock_all_shards();  // readers hold one: hold them all
  if (ranges_.size() == ranges_.capacity()) ranges_.reserve(2 * ranges_.size() + 8);  // may throw: nothing changed yet
  const std::uint64_t to_compact = close_open_range();  // its tickets end where r's begin
  ranges_.push_back(r.release());  // the largest first: still sorted
  return to_compact;
}

TicketTable::Issued TicketTable::issue(std::uint64_t n) {
  assert(n >= 1 && n < (std::uint64_t{1} << 31));
  std::uint64_t to_compact = no_range;
  Issued out;
  {
    std::lock_guard issuing(issue_mutex_);
    const std::uint64_t first = next_.load(std::memory_order_relaxed);
    if (!open_ || first + n > open_->first + open_->n) {
      // Made before anything changes: a failure issues nothing.
      std::unique_ptr<TicketRange> r =
          make_range(first, static_cast<std::uint32_t>(n <= open_size_ ? open_size_ : n + open_size_));
      TicketRange* opened = r.get();
      to_compact = add_range(std::move(r));
      open_ = opened;
    }
    live_.fetch_add(n, std::memory_order_relaxed);
    next_.store(first + n, std::memory_order_release);
    out = {first, open_};
    // Full: an ordinary range from now on, which compact may free.
    if (first + n == open_->first + open_->n) {
      open_ = nullptr;
      open_size_ = std::min(2 * open_size_, open_range_max);
    }
  }
  compact(to_compact);
  return out;
}

TicketTable::Issued TicketTable::issue_ordered(std::span<const std::uint32_t> order) {
  const std::size_t n = order.size();
  if (n < range_min) return issue(n);
  std::uint64_t to_compact = no_range;
  Issued out;
  // The range is made for the tickets that come next now, outside the mutex
  // and in parallel (1M slots: 16 ms on one thread), and issued if no other
  // issue came in between; else made again. After a few tries, under the
  // mutex on this thread, so a stream of other issues cannot hold it off.
  for (int tries = 0;; ++tries) {
    const bool last_try = tries == 3;
    std::unique_lock issuing(issue_mutex_, std::defer_lock);
    if (last_try) issuing.lock();
    const std::uint64_t first = next_.load(std::memory_order_acquire);
    std::unique_ptr<TicketRange> r = make_range(first, static_cast<std::uint32_t>(n), order.data(), !last_try);
    if (!last_try) issuing.lock();
    if (next_.load(std::memory_order_relaxed) != first) continue;  // another issue came first
    out = {first, r.get()};
    to_compact = add_range(std::move(r));
    live_.fetch_add(n, std::memory_order_relaxed);
    next_.store(first + n, std::memory_order_release);
    break;
  }
  compact(to_compact);
  return out;
}

TicketView TicketTable::claim_undo(std::uint64_t t, const StableArray<VertexRec>& verts) {
  if (t >= next_.load(std::memory_order_acquire)) unknown(t, "no such insertion was submitted");
  const char* why = nullptr;
  std::uint64_t to_compact = no_range;
  TicketView view;
  {
    Shard& s = shard(t);
    std::lock_guard lock(s.mutex);
    Slot* slot = find(t);
    if (!slot) {
      why = "it was already undone, or its vertex was removed meanwhile";
    } else if (slot->undone) {
      why = "it was already undone";
    } else if (slot->state == TicketState::failed) {
      s.errors.erase(t);
      to_compact = erase(t, slot);
      why = "that insertion failed";
    } else if (vertex_gone(*slot, verts)) {
      to_compact = erase(t, slot);
      why = "its vertex was removed meanwhile (by handle or id)";
    } else {
      slot->undone = true;
      view = {slot->state, slot->vertex, slot->stamp};
    }
  }
  compact(to_compact);
  if (why) unknown(t, why);
  return view;
}

void TicketTable::unclaim_undo(std::uint64_t t) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  if (Slot* slot = find(t)) slot->undone = false;
}

TicketView TicketTable::view(std::uint64_t t) const {
  const Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  const Slot* slot = find(t);
  if (!slot) return {TicketState::failed, no_vertex, 0};
  return {slot->state, slot->vertex, slot->stamp};
}

OpRecord* TicketTable::park(std::uint64_t t, OpRecord* undo) {
  Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  Slot* slot = find(t);
  if (!slot || slot->state != TicketState::pending) return undo;  // done meanwhile: run it now
  slot->parked = undo;
  return nullptr;
}

template <class Write>
OpRecord* TicketTable::finish(std::uint64_t t, TicketPosition at, Write&& write) {
  OpRecord* undo = nullptr;
  std::uint64_t to_compact = no_range;
  {
    Shard& s = shard(t);
    std::lock_guard lock(s.mutex);
    TicketRange* range = nullptr;
    Slot* slot = find(t, at, &range);
    if (range) to_compact = finished_in(*range, t);
    write(*slot, s);
    undo = slot->parked;
    slot->parked = nullptr;
  }
  compact(to_compact);
  return undo;
}

OpRecord* TicketTable::finish_inserted(std::uint64_t t, VertexId v, bool inserted, std::uint64_t stamp,
                                       TicketPosition at) {
  return finish(t, at, [&](Slot& slot, Shard&) {
    slot.state = TicketState::inserted;
    slot.vertex = v;
    slot.inserted = inserted;
    slot.stamp = stamp;
  });
}

OpRecord* TicketTable::finish_failed(std::uint64_t t, std::exception_ptr error, TicketPosition at) {
  return finish(t, at, [&](Slot& slot, Shard& s) {
    slot.state = TicketState::failed;
    try {
      s.errors[t] = std::move(error);
    } catch (...) {
      // No room to keep the error: insertion_result(t) will say it failed without it.
    }
  });
}

std::uint64_t TicketTable::finished_in(TicketRange& range, std::uint64_t t) {
  std::atomic<std::uint32_t>& pending = range.counts[t % shard_count].pending;
  decrement(pending);
  // Looked at only when this shard's share runs out (16 times a range), not
  // at every finish: mostly_released reads every shard's counts.
  return pending.load(std::memory_order_relaxed) == 0 && range.mostly_released() ? range.first : no_range;
}

void TicketTable::release(std::uint64_t t) {
  std::uint64_t to_compact = no_range;
  {
    Shard& s = shard(t);
    std::lock_guard lock(s.mutex);
    if (Slot* slot = find(t)) {
      s.errors.erase(t);
      to_compact = erase(t, slot);
    }
  }
  compact(to_compact);
}

InsertResult TicketTable::result(std::uint64_t t, const StableArray<VertexRec>& verts) const {
  if (t >= next_.load(std::memory_order_acquire))
    throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) + " was never submitted");
  const Shard& s = shard(t);
  std::lock_guard lock(s.mutex);
  const Slot* slot = find(t);
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
  // A done insertion whose vertex incarnation is gone can no longer be
  // undone by ticket (an undo claimed for it will fail on its own).
  auto dead = [&](const Slot& slot) { return slot.key != 0 && !slot.undone && vertex_gone(slot, verts); };
  std::uint64_t erased = 0;
  for (Shard& s : shards_) {
    std::lock_guard lock(s.mutex);
    for (std::size_t i = 0; i < s.slots.size();) {
      if (dead(s.slots[i])) {
        s.erase(&s.slots[i]);  // the next entry may have shifted into i: look at i again
        ++erased;
      } else {
        ++i;
      }
    }
  }
  std::vector<std::uint64_t> to_compact;
  {
    const auto locks = lock_all_shards();
    for (TicketRange* r : ranges_) {
      for (std::uint32_t k = 0; k < r->n; ++k) {
        Slot& slot = r->slots[k];
        if (!dead(slot)) continue;
        decrement(r->counts[(slot.key - 1) % shard_count].live);
        slot = Slot{};
        ++erased;
      }
      if (r->mostly_released()) {
        try {
          to_compact.push_back(r->first);
        } catch (const std::bad_alloc&) {
          // Compacted at a later release or sweep.
        }
      }
    }
  }
  for (std::uint64_t first : to_compact) compact(first);
  const std::uint64_t before = live_.fetch_sub(erased, std::memory_order_relaxed);
  // Next sweep when the table doubles past what is live now (amortised O(1)).
  // Tickets issued during the sweep may be among the erased (issue() counts
  // them in live_ after inserting them), so neither live_now - erased nor
  // before - erased is sure to be >= 0: clamp, never wrap.
  const std::uint64_t left = before > erased ? before - erased : 0;
  sweep_at_.store(2 * std::max<std::uint64_t>(left, live_vertices) + (1 << 16), std::memory_order_relaxed);
}

}  // namespace pdt::detail
