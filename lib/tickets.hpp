// SPDX-License-Identifier: MIT
#pragma once
// Tickets: insertion t of an engine is ticket t. While it can still be used,
// its slot records the insertion's state and, once it is done, the vertex
// incarnation it made, so that remove_insertion(t) finds the vertex; an undo
// that arrives before the insertion is done waits (parks) on the slot.
//
// Memory follows what can still be referenced, not what was ever submitted:
// a slot is erased when its undo has run, and slots whose vertex is gone
// (removed by handle or id) are swept once they outnumber the live vertices.
// The slots live in 16 shards (ticket mod 16), each an open-addressing table
// with backward-shift deletion under its own mutex. 16, not more: a finish
// holds its shard for one find, and at 1M live tickets a shard's slots fill
// 4 MiB, large enough for huge pages (SlotAllocator, when advised); a batch finishes in
// spatial order, so each find lands on a random slot.
// Invariants: a slot exists for every ticket issued and not released;
// pending slots are never swept; a parked undo exists only on a pending slot.
#include <atomic>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "op_record.hpp"
#include "storage.hpp"
#include "stable_array.hpp"

namespace pdt::detail {

enum class TicketState : std::uint8_t { pending, inserted, failed };

// What an undo needs to know of its insertion.
struct TicketView {
  TicketState state = TicketState::pending;
  VertexId vertex = no_vertex;
  std::uint64_t stamp = 0;
};

class TicketTable {
 public:
  // Issues n consecutive tickets; returns the first. Throws std::bad_alloc
  // (and issues none) if a shard cannot grow.
  std::uint64_t issue(std::uint64_t n);
  std::uint64_t issued() const { return next_.load(std::memory_order_relaxed); }
  std::uint64_t live() const { return live_.load(std::memory_order_relaxed); }
  // Fetches the cache line where t's slot most likely is (its home), without
  // the shard's lock: an insertion calls it when it starts, so that
  // finish_inserted, microseconds later, does not wait for memory (the slots
  // are scattered by hash and a batch finishes in spatial, not ticket, order).
  // A hint only: it reads nothing, and may fetch a stale line while the shard
  // is being resized.
  void prefetch(std::uint64_t t) const;

  // Claims the undo of t; throws pdt::Error(unknown_vertex) for a ticket
  // never issued, released, already undone, or whose insertion failed or
  // whose vertex is gone (those two are then released). unclaim gives a
  // claim back.
  TicketView claim_undo(std::uint64_t t, const StableArray<VertexRec>& verts);
  void unclaim_undo(std::uint64_t t);
  // The state of t for an undo about to run (t was claimed, so it exists).
  TicketView view(std::uint64_t t) const;
  // An undo of t found it pending: parks it. Returns the undo back when the
  // insertion finished meanwhile (the caller runs it), else nullptr.
  OpRecord* park(std::uint64_t t, OpRecord* undo);
  // Records insertion t's outcome; returns an undo parked on it, to re-queue.
  OpRecord* finish_inserted(std::uint64_t t, VertexId v, bool inserted, std::uint64_t stamp);
  OpRecord* finish_failed(std::uint64_t t, std::exception_ptr error);
  // t's undo ran: its slot goes.
  void release(std::uint64_t t);
  // The outcome of a finished insertion (rethrows its error); throws
  // pdt::Error(invalid_argument) if t was never issued, is not finished, or
  // was released (its vertex is gone: released, though a sweep may not have
  // erased its slot yet).
  InsertResult result(std::uint64_t t, const StableArray<VertexRec>& verts) const;
  // Erases the done slots whose vertex incarnation is gone, if the table has
  // grown well past `live_vertices`.
  void sweep_if_large(const StableArray<VertexRec>& verts, std::uint64_t live_vertices);

 private:
  struct Slot {
    std::uint64_t key = 0;  // ticket + 1; 0 = empty
    std::uint64_t stamp = 0;
    OpRecord* parked = nullptr;
    VertexId vertex = no_vertex;
    TicketState state = TicketState::pending;
    bool inserted = false;
    bool undone = false;
  };
  // The slots' memory: blocks of 2 MiB and more, 2 MiB-aligned, so that with
  // PDT_HUGE_PAGES=1 (huge_pages.hpp) they lie on transparent huge pages and
  // the scattered finds of a large batch do not miss the TLB each time.
  template <class T>
  struct SlotAllocator {
    using value_type = T;
    SlotAllocator() = default;
    template <class U>
    SlotAllocator(const SlotAllocator<U>&) noexcept {}
    T* allocate(std::size_t n);
    void deallocate(T* p, std::size_t n) noexcept;
    bool operator==(const SlotAllocator&) const = default;
  };
  struct alignas(64) Shard {
    mutable std::mutex mutex;
    std::vector<Slot, SlotAllocator<Slot>> slots;  // power of two (or empty), at most half full
    // slots.data() and slots.size() - 1 for prefetch(), which reads them
    // without the mutex; written under it whenever slots is replaced.
    std::atomic<std::uintptr_t> prefetch_base{0};
    std::atomic<std::size_t> prefetch_mask{0};
    std::size_t count = 0;
    std::unordered_map<std::uint64_t, std::exception_ptr> errors;  // failed insertions
    Slot* find(std::uint64_t t);
    const Slot* find(std::uint64_t t) const;
    void insert(std::uint64_t t);  // room must exist
    void reserve(std::size_t n);
    void erase(Slot* s);
  };
  static constexpr unsigned shard_count = 16;
  Shard& shard(std::uint64_t t) { return shards_[t % shard_count]; }
  const Shard& shard(std::uint64_t t) const { return shards_[t % shard_count]; }
  [[noreturn]] static void unknown(std::uint64_t t, const char* why);
  // A done insertion whose vertex incarnation is gone (removed by handle or
  // id, perhaps the id reused since): its ticket is released, whether or not
  // a sweep has erased the slot yet.
  static bool vertex_gone(const Slot& slot, const StableArray<VertexRec>& verts) {
    return slot.state == TicketState::inserted && verts[slot.vertex].stamp.load(std::memory_order_relaxed) != slot.stamp;
  }
  Shard shards_[shard_count];
  std::atomic<std::uint64_t> next_{0};
  std::atomic<std::uint64_t> live_{0};
  std::atomic<std::uint64_t> sweep_at_{1 << 16};
  std::mutex issue_mutex_;
};

}  // namespace pdt::detail
