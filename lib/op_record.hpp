// SPDX-License-Identifier: MIT
#pragma once
// OpRecord: one submitted operation while it waits in a queue, waits on a
// ticket, or runs; and the pool that recycles records, so that submitting
// allocates nothing once warm.
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "pdt/engine.hpp"
#include "raw_array.hpp"

namespace pdt::detail {

struct TicketRange;  // tickets.hpp

// What the operations of a batch share: one callback, and for insert_batch
// the points themselves, in insertion (spatial) order. Freed by the last
// operation to complete.
struct BatchCallback {
  Engine::Callback fn;
  std::atomic<std::uint64_t> remaining{0};
  RawArray<Point3> points;             // insert_batch: in insertion order, point_count() of them
  std::vector<std::uint32_t> index;    // points[k] is the caller's points[index[k]]: ticket first_ticket + index[k]
  std::uint64_t first_ticket = 0;
  TicketRange* ticket_range = nullptr;  // insert_batch: the range of its tickets' slots (tickets.hpp)
  std::size_t point_count() const { return index.size(); }  // insert_batch's; 0 for other batches
};

struct OpRecord {
  std::atomic<OpRecord*> next{nullptr};  // BlockQueue's link; the pool's too
  OpKind kind = OpKind::insert;
  bool from_batch = false;      // insert: part of a spatially sorted batch (walk from the last vertex)
  bool routed = true;           // false: `point` unknown yet; the worker that pops it reads it and re-routes
  bool only_if_alive = false;   // insert: only if `cell` is alive (no ticket then)
  std::uint32_t rollbacks = 0;  // times this operation met a lock (escalates at escalate_after)
  Point3 point;                 // insert: the point; others: where it runs (routing)
  VertexId vertex = no_vertex;  // remove
  std::uint64_t stamp = 0;      // remove: the vertex incarnation expected (0 = any)
  std::uint64_t ticket = 0;     // insert: its own ticket; remove_insertion: the insertion undone
  CellHandle cell;              // visit
  CellVisitor visitor;          // visit
  Engine::Callback done;
  BatchCallback* batch_done = nullptr;
  OpAwaitBase* awaiter = nullptr;
  // A run of an insert_batch: its points [run_next, run_end) of
  // batch_done->points, consecutive in insertion order and in one block,
  // waiting as one record; a worker serves them one after the other, each as
  // a record of its own (`point` is then the next one's, for routing).
  // run_end == 0: not a run. Invariant: run_next < run_end while queued.
  std::uint32_t run_next = 0, run_end = 0;
  // An insertion with a ticket: where the ticket's slot is (slot ticket_slot
  // of ticket_range), for its finish. Set at submission, or when a run's
  // point is taken; the range lives while the ticket is pending.
  TicketRange* ticket_range = nullptr;
  std::uint32_t ticket_slot = 0;
};

// Records come in slabs (256 records at first, 1024 from the fifth slab on;
// a shard list may keep most of a slab unused, so slabs of 8192 added 3 MB to
// a 16-worker batch's peak) and are recycled through free lists, one per shard
// (a thread uses the shard its id hashes to), each under its own mutex.
// The first thread to acquire a record (the one that built the engine, as a
// rule: the client's submitting thread) owns a front list besides, which it
// alone touches, without a lock: it refills it by taking a shard's whole list
// at once, so that a single thread feeding many workers takes one shard mutex
// per list, not one per record (each a line the releasing worker last wrote).
// Invariant: every record is either on a free list (a shard's or the front)
// or owned by exactly one submitted operation.
class OpRecordPool {
 public:
  OpRecordPool();
  ~OpRecordPool();
  OpRecordPool(const OpRecordPool&) = delete;
  OpRecordPool& operator=(const OpRecordPool&) = delete;
  OpRecord* acquire();          // throws std::bad_alloc (nothing changed)
  void release(OpRecord* op);   // resets the record; never fails
  static void reset(OpRecord* op);  // as a fresh record, but for `next` and `kind`

 private:
  static constexpr unsigned shards = 16;
  struct alignas(64) Shard {
    std::mutex mutex;
    OpRecord* head = nullptr;
  };
  static unsigned my_shard();
  OpRecord* acquire_front();  // by the front's owner only
  OpRecord* take_list();      // a whole shard list, or else a fresh slab's records, linked
  struct Fresh {
    OpRecord* first;
    OpRecord* last;
  };
  Fresh fresh_records();  // a new slab's records, linked first to last; throws std::bad_alloc
  struct SlabDeleter {
    std::size_t count = 0;
    void operator()(OpRecord* records) const noexcept;
  };
  using Slab = std::unique_ptr<OpRecord[], SlabDeleter>;
  static Slab make_slab(std::size_t count);  // throws std::bad_alloc
  Shard shards_[shards];
  // The front list's owner (a thread_token(), 0: none yet), read by every
  // acquire, and the list, written by the owner's: on lines of their own.
  struct alignas(64) Front {
    std::atomic<std::uintptr_t> owner{0};
    alignas(64) OpRecord* head = nullptr;
  };
  Front front_;
  std::mutex slab_mutex_;
  std::vector<Slab> slabs_;
};

}  // namespace pdt::detail
