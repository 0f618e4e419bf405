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
// Issued tickets get ranges of slots (TicketRange). A large batch
// (issue_ordered) gets one of its own, its slots in the order the engine
// runs its insertions (spatial, not ticket order), so that the workers
// finishing them write memory nearly in sequence rather than one random
// slot (a cache and TLB miss) each, with a table from ticket to slot for the
// lookups by ticket. Tickets issued one at a time (and small batches) are
// given out of the open range: a range of slots in ticket order, made ahead
// and keyed when made, so that issuing one takes no shard lock and writes no
// slot, and the slots of the tickets in flight lie together. The next large
// batch, or a request that does not fit, closes it (shrinks it to the
// tickets it gave out). Its size starts at open_range_min and doubles, up
// to open_range_max, each time one fills up; a close starts it again at
// the minimum, so what a closed range leaves unused is at most its size:
// 64 slots while single tickets and large batches alternate, and never more
// than twice the tickets given out since the previous close. A request of
// more tickets than the open size gets a range of that many more. A range's
// slot is guarded by its ticket's shard mutex; the list of ranges changes
// only with every shard mutex held, so any one held shard mutex keeps it
// still.
// Once at most an eighth of a range's slots hold live tickets and none is
// pending, the live ones move to the shards and the range goes (compact), so
// memory still follows what can be referenced. Whatever makes that so checks
// it: an erase, a sweep, a close, and a finish that leaves a range's share of
// a shard with none pending. The shards: 16 (ticket mod 16), each
// an open-addressing table with backward-shift deletion under its own mutex,
// holding the compacted tickets; a shard's consecutive tickets four to an
// aligned group of slots (home_slot in tickets.cpp). At 1M live tickets a
// shard's slots fill 4 MiB, large enough for huge pages (SlotAllocator,
// when advised).
// Invariants: a slot exists for every ticket issued and not released (a
// range's released slot has key 0); pending slots are never swept; a parked
// undo exists only on a pending slot; a range with a pending slot is never
// compacted (an insertion's TicketPosition points into it until it finishes).
// The open range, if any, is the last range; its slots past the tickets
// issued are keyed and counted live and pending (so it is never compacted
// while open), and no lookup reaches them: every lookup by ticket is of a
// ticket issued (claim_undo and result check, the rest are the engine's own).
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
#include "raw_array.hpp"
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

// The slots of tickets [first, first + n): a large batch's in run order, or
// the open range's in ticket order (position null).
struct TicketRange {
  std::uint64_t first = 0;
  std::uint32_t n = 0;
  std::uint32_t capacity = 0;  // slots allocated: n, or more once a close has shrunk n
  RawArray<TicketSlot> slots;                 // slot k: the k-th ticket to run (ticket first + k if no position); all written by make_range
  std::unique_ptr<std::uint32_t[]> position;  // position[t - first]: t's slot; null: slot t - first
  std::uint32_t slot_of(std::uint64_t t) const {
    return position ? position[t - first] : static_cast<std::uint32_t>(t - first);
  }
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
  // then) and at most an eighth of its slots live: of those allocated, not
  // n, so that a range closed after a few tickets goes once they finish.
  bool mostly_released() const { return !any_pending() && live_now() <= capacity / 8; }
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

  struct Issued {
    std::uint64_t first = 0;
    TicketRange* range = nullptr;  // where their slots are: ticket t's is range->slot_of(t)
  };
  // Issues n consecutive tickets (1 <= n < 2^31) out of the open range, a
  // new one (of open_size_ slots, or n + open_size_ if n is more) if it has
  // no room for them. Throws std::bad_alloc (and issues none) if a new range
  // cannot be made.
  static constexpr std::uint32_t open_range_min = 64, open_range_max = 4096;
  Issued issue(std::uint64_t n);
  // Issues order.size() consecutive tickets that will run in this order: the
  // k-th to run is ticket first + order[k] (order: a permutation of 0..n-1).
  // From range_min tickets on they get a range of their own, whose slot k is
  // that ticket's (position set); fewer are issued as issue's. Throws
  // std::bad_alloc (and issues none).
  static constexpr std::size_t range_min = 1024;
  Issued issue_ordered(std::span<const std::uint32_t> order);
  // Tickets whose slots are in ranges now, and the slots allocated in all
  // (ranges and shards), for tests.
  std::size_t ranged() const;
  std::size_t slots_allocated() const;
  std::uint64_t issued() const { return next_.load(std::memory_order_relaxed); }
  std::uint64_t live() const { return live_.load(std::memory_order_relaxed); }
  // Fetches the cache line of the slot at `at`, without the shard's lock: an
  // insertion calls it when it starts, so that finish_inserted, microseconds
  // later, does not wait for memory (the engine finishes insertions in
  // spatial, not ticket, order). A hint only: it reads nothing.
  static void prefetch(TicketPosition at) {
    if (at.range) __builtin_prefetch(&at.range->slots[at.k], 1);
  }

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
    std::unordered_map<std::uint64_t, std::exception_ptr> errors;  // failed insertions
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
  // Counts t (of `range`) as no longer pending; the caller holds
  // shard(t).mutex. Returns the range's first ticket when it is now worth
  // compacting (no_range if not), for compact once the mutex is let go.
  static std::uint64_t finished_in(TicketRange& range, std::uint64_t t);
  // finish_inserted and finish_failed: t's slot, found under its shard's
  // mutex, written by write(slot, shard); returns the undo parked on it.
  template <class Write>
  OpRecord* finish(std::uint64_t t, TicketPosition at, Write&& write);
  // Moves the live slots of the range starting at ticket `first` to the
  // shards and frees it, if it still exists and is mostly_released() (else,
  // or if the shards cannot grow, nothing happens). By ticket, not pointer:
  // another thread may have compacted it meanwhile. Takes issue_mutex_, then
  // every shard mutex.
  void compact(std::uint64_t first);
  // A range of n slots for tickets [first, first + n), keyed, all counted
  // live and pending: in run order if `order` is given (slot k holds ticket
  // first + order[k]; position set), else in ticket order (position null).
  // parallel: its slots are written on the arena's threads (never under a
  // mutex: the calling thread may take other tasks meanwhile).
  // Throws std::bad_alloc.
  static std::unique_ptr<TicketRange> make_range(std::uint64_t first, std::uint32_t n,
                                                 const std::uint32_t* order = nullptr, bool parallel = false);
  // Shrinks the open range to the tickets it gave out and forgets it. The
  // caller holds issue_mutex_ and every shard mutex. Returns the range's
  // first ticket if it is now worth compacting, else no_range.
  std::uint64_t close_open_range();
  // Appends r (its tickets next after every issued one) to ranges_, closing
  // the open range first, under every shard mutex; the caller holds
  // issue_mutex_. Returns what close_open_range does. Throws std::bad_alloc
  // (changing nothing, r freed) if ranges_ cannot grow.
  std::uint64_t add_range(std::unique_ptr<TicketRange> r);
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
  // By first ticket. Changed (add_range, compact) only with every shard
  // mutex held; read with any one held.
  std::vector<TicketRange*> ranges_;
  // The range single tickets are issued from, or null (none yet, or the
  // last one filled up); ranges_.back() if set, and never full. Read and
  // written under issue_mutex_.
  TicketRange* open_ = nullptr;
  std::uint32_t open_size_ = open_range_min;  // the next open range's size (issue_mutex_)
  std::atomic<std::uint64_t> next_{0};
  std::atomic<std::uint64_t> live_{0};
  std::atomic<std::uint64_t> sweep_at_{1 << 16};
  mutable std::mutex issue_mutex_;
};

}  // namespace pdt::detail
