// SPDX-License-Identifier: MIT
#include "op_record.hpp"

#include <functional>
#include <thread>

#include "fault_injection.hpp"

namespace pdt::detail {

OpRecordPool::OpRecordPool() = default;
OpRecordPool::~OpRecordPool() = default;

unsigned OpRecordPool::my_shard() {
  thread_local const unsigned shard =
      static_cast<unsigned>(std::hash<std::thread::id>()(std::this_thread::get_id()) % shards);
  return shard;
}

OpRecord* OpRecordPool::acquire() {
  const unsigned home = my_shard();
  // Records go back to the shard of the thread that completes them (a
  // worker's), so a submitter's own shard is often empty: it looks first
  // where it found one last, then from its own on.
  thread_local unsigned found_last = shards;
  auto take = [&](unsigned at) -> OpRecord* {
    Shard& s = shards_[at];
    std::lock_guard lock(s.mutex);
    OpRecord* op = s.head;
    if (op) {
      s.head = op->next.load(std::memory_order_relaxed);
      found_last = at;
    }
    return op;
  };
  if (found_last < shards)
    if (OpRecord* op = take(found_last)) return op;
  for (unsigned k = 0; k < shards; ++k)
    if (OpRecord* op = take((home + k) % shards)) return op;
  constexpr std::size_t slab = 1024;
  PDT_FAULT_POINT("op record slab");
  auto fresh = std::make_unique<OpRecord[]>(slab);
  OpRecord* first = fresh.get();
  {
    std::lock_guard lock(slab_mutex_);
    slabs_.push_back(std::move(fresh));
  }
  Shard& s = shards_[home];
  std::lock_guard lock(s.mutex);
  for (std::size_t i = 1; i < slab; ++i) {
    first[i].next.store(s.head, std::memory_order_relaxed);
    s.head = &first[i];
  }
  return first;
}

void OpRecordPool::reset(OpRecord* op) {
  op->done = nullptr;
  op->visitor = nullptr;
  op->batch_done = nullptr;
  op->awaiter = nullptr;
  op->from_batch = false;
  op->routed = true;
  op->only_if_alive = false;
  op->rollbacks = 0;
  op->stamp = 0;
  op->vertex = no_vertex;
  op->run_next = op->run_end = 0;
  op->ticket_range = nullptr;
  op->ticket_slot = 0;
}

void OpRecordPool::release(OpRecord* op) {
  reset(op);
  Shard& s = shards_[my_shard()];
  std::lock_guard lock(s.mutex);
  op->next.store(s.head, std::memory_order_relaxed);
  s.head = op;
}

}  // namespace pdt::detail
