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

namespace pdt::detail {

// One callback shared by the operations of a batch: freed by the last one.
struct BatchCallback {
  Engine::Callback fn;
  std::atomic<std::uint64_t> remaining{0};
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
};

// Records come in slabs and are recycled through free lists, one per shard
// (a thread uses the shard its id hashes to), each under its own mutex.
// Invariant: every record is either on a free list or owned by exactly one
// submitted operation.
class OpRecordPool {
 public:
  OpRecordPool();
  ~OpRecordPool();
  OpRecordPool(const OpRecordPool&) = delete;
  OpRecordPool& operator=(const OpRecordPool&) = delete;
  OpRecord* acquire();          // throws std::bad_alloc (nothing changed)
  void release(OpRecord* op);   // resets the record; never fails

 private:
  static constexpr unsigned shards = 16;
  struct alignas(64) Shard {
    std::mutex mutex;
    OpRecord* head = nullptr;
  };
  static unsigned my_shard();
  Shard shards_[shards];
  std::mutex slab_mutex_;
  std::vector<std::unique_ptr<OpRecord[]>> slabs_;
};

}  // namespace pdt::detail
