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
// Tickets issued one at a time (and small batches) have their slots in 16
// shards (ticket mod 16), each an open-addressing table with backward-shift
// deletion under its own mutex; a shard's consecutive tickets four to an
// aligned group of slots (home_slot in tickets.cpp). 16, not more: a finish holds its shard for
// one find, and at 1M live tickets a shard's slots fill 4 MiB, large enough
// for huge pages (SlotAllocator, when advised).
// A large batch (issue_ordered) gets a range instead (TicketRange): its slots
// in the order the engine runs its insertions (spatial, not ticket order),
// so that the workers finishing them write memory nearly in sequence rather
// than one random slot (a cache and TLB miss) each, and a table from ticket
// to slot for the lookups by ticket. A range's slot is guarded by its
// ticket's shard mutex like a hashed one; the list of ranges changes only
// with every shard mutex held, so any one held shard mutex keeps it still.
// Once at most an eighth of a range's tickets are live and none is pending,
// the live ones move to the shards and the range goes (compact), so memory
// still follows what can be referenced.
// Invariants: a slot exists for every ticket issued and not released (a
// range's released slot has key 0); pending slots are never swept; a parked
// undo exists only on a pending slot; a range with a pending slot is never
// compacted (an insertion's TicketPosition points into it until it finishes).
#include <array>
#include <atomic>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <span>
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

// A ticket's slot.
struct TicketSlot {
  std::uint64_t key = 0;  // ticket + 1; 0 = empty (released)
  std::uint64_t stamp = 0;
  OpRecord* parked = nullptr;
  VertexId vertex = no_vertex;
  TicketState state = TicketState::pending;
  bool inserted = false;
  bool undone = false;
};

inline constexpr unsigned ticket_shards = 16;

// The slots of a large batch's tickets [first, first + n), in run order.
struct TicketRange {
  std::uint64_t first = 0;
  std::uint32_t n = 0;
  std::unique_ptr<TicketSlot[]> slots;        // slot k: the k-th ticket to run
  std::unique_ptr<std::uint32_t[]> position;  // position[t - first]: t's slot
  // Of the range's tickets t with t % ticket_shards == j: how many are live
  // (not released) and how many pending, in counts[j]; written under shard
  // j's mutex, read without it (relaxed) to decide whether to compact. One
  // cache line each: workers finishing tickets of two shards do not share one.
  struct alignas(64) Counts {
    std::atomic<std::uint32_t> live{0}, pending{0};
  };
  Counts counts[ticket_shards];
  std::uint32_t live_now() const {
    std::uint32_t sum = 0;
    for (const Counts& c : counts) sum += c.live.load(std::memory_order_relaxed);
    return sum;
  }
  bool any_pending() const {
    for (const Counts& c : counts)
      if (c.pending.load(std::memory_order_relaxed) != 0) return true;
    return false;
  }
  // Worth compacting: none pending (TicketPosition may point into it until
  // then) and at most an eighth live.
  bool mostly_released() const { return !any_pending() && live_now() <= n / 8; }
};

// Where a ranged ticket's slot is: for finish_*, which then need no lookup.
struct TicketPosition {
  TicketRange* range = nullptr;  // null: look the ticket up
  std::uint32_t k = 0;
};

class TicketTable {
 public:
  TicketTable() = default;
  TicketTable(const TicketTable&) = delete;
  TicketTable& operator=(const TicketTable&) = delete;
  ~TicketTable();

  // Issues n consecutive tickets; returns the first. Throws std::bad_alloc
  // (and issues none) if a shard cannot grow.
  std::uint64_t issue(std::uint64_t n);
  // Issues order.size() consecutive tickets that will run in this order: the
  // k-th to run is ticket first + order[k] (order: a permutation of 0..n-1).
  // From range_min tickets on they get a range, returned (else null: hashed
  // like issue's), whose slot k is that ticket's. Throws std::bad_alloc (and
  // issues none).
  static constexpr std::size_t range_min = 1024;
  struct Issued {
    std::uint64_t first = 0;
    TicketRange* range = nullptr;
  };
  Issued issue_ordered(std::span<const std::uint32_t> order);
  // Tickets whose slots are in ranges now (for tests).
  std::size_t ranged() const;
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
  // at: where t's slot is, if issue_ordered put it in a range.
  OpRecord* finish_inserted(std::uint64_t t, VertexId v, bool inserted, std::uint64_t stamp, TicketPosition at = {});
  OpRecord* finish_failed(std::uint64_t t, std::exception_ptr error, TicketPosition at = {});
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
  using Slot = TicketSlot;
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
    std::size_t count = 0;
    // slots.data() and slots.size() - 1 for prefetch(), which reads them
    // without the mutex; written under it whenever slots is replaced. On a
    // line of their own: a worker reads them for each insertion while a
    // submitter writes count and the mutex for each ticket it issues.
    alignas(64) std::atomic<std::uintptr_t> prefetch_base{0};
    std::atomic<std::size_t> prefetch_mask{0};
    alignas(64) std::unordered_map<std::uint64_t, std::exception_ptr> errors;  // failed insertions
    Slot* find(std::uint64_t t);
    const Slot* find(std::uint64_t t) const;
    void insert(std::uint64_t t);  // room must exist
    void reserve(std::size_t n);
    void erase(Slot* s);
  };
  static constexpr unsigned shard_count = ticket_shards;
  Shard& shard(std::uint64_t t) { return shards_[t % shard_count]; }
  const Shard& shard(std::uint64_t t) const { return shards_[t % shard_count]; }
  // The range holding t, or null. The caller holds a shard mutex.
  TicketRange* range_of(std::uint64_t t) const;
  // t's slot, in its range (then *range is set) or its shard; null if
  // released or never issued. The caller holds shard(t).mutex.
  Slot* find(std::uint64_t t, TicketPosition at = {}, TicketRange** range = nullptr);
  const Slot* find(std::uint64_t t) const { return const_cast<TicketTable*>(this)->find(t); }
  // Releases t's slot (from find(t)) and counts it out of live_; the caller
  // holds shard(t).mutex. Returns the first ticket of t's range when the
  // range is now worth compacting (no_range if not): the caller passes it
  // to compact after letting the mutex go.
  static constexpr std::uint64_t no_range = ~std::uint64_t{0};
  std::uint64_t erase(std::uint64_t t, Slot* slot);
  // Moves the live slots of the range starting at ticket `first` to the
  // shards and frees it, if it still exists and is mostly_released() (else,
  // or if the shards cannot grow, nothing happens). By ticket, not pointer:
  // another thread may have compacted it meanwhile. Takes issue_mutex_, then
  // every shard mutex.
  void compact(std::uint64_t first);
  // Every shard mutex, taken in index order (after issue_mutex_ where that is
  // taken too): what changing ranges_ needs, and a sweep of the ranges.
  std::array<std::unique_lock<std::mutex>, shard_count> lock_all_shards() const;
  [[noreturn]] static void unknown(std::uint64_t t, const char* why);
  // A done insertion whose vertex incarnation is gone (removed by handle or
  // id, perhaps the id reused since): its ticket is released, whether or not
  // a sweep has erased the slot yet.
  static bool vertex_gone(const Slot& slot, const StableArray<VertexRec>& verts) {
    return slot.state == TicketState::inserted && verts[slot.vertex].stamp.load(std::memory_order_relaxed) != slot.stamp;
  }
  Shard shards_[shard_count];
  // By first ticket. Changed (issue_ordered, compact) only with every shard
  // mutex held; read with any one held.
  std::vector<TicketRange*> ranges_;
  std::atomic<std::uint64_t> next_{0};
  std::atomic<std::uint64_t> live_{0};
  std::atomic<std::uint64_t> sweep_at_{1 << 16};
  std::mutex issue_mutex_;
};

}  // namespace pdt::detail
