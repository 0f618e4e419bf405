// SPDX-License-Identifier: MIT
#include "op_record.hpp"

#include <sys/mman.h>

#include <cstdint>
#include <functional>
#include <new>
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

void OpRecordPool::SlabDeleter::operator()(OpRecord* records) const noexcept {
  for (std::size_t i = 0; i < count; ++i) records[i].~OpRecord();
  ::operator delete(static_cast<void*>(records), std::align_val_t{alignof(OpRecord)});
}

// The slab's pages are committed in one system call before its records are
// constructed: a submitter that outruns the workers (a million insertions
// submitted at once) would otherwise take a page fault every 22 records.
OpRecordPool::Slab OpRecordPool::make_slab(std::size_t count) {
  const std::size_t bytes = count * sizeof(OpRecord);
  void* raw = ::operator new(bytes, std::align_val_t{alignof(OpRecord)});
#ifdef MADV_POPULATE_WRITE
  constexpr std::uintptr_t page = 4096;
  const auto begin = (reinterpret_cast<std::uintptr_t>(raw) + page - 1) & ~(page - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(raw) + bytes) & ~(page - 1);
  if (begin < end) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_POPULATE_WRITE);  // advice only
#endif
  auto* records = static_cast<OpRecord*>(raw);
  for (std::size_t i = 0; i < count; ++i) new (&records[i]) OpRecord();  // noexcept
  return Slab(records, SlabDeleter{count});
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
  PDT_FAULT_POINT("op record slab");
  std::size_t slab;
  {
    std::lock_guard lock(slab_mutex_);
    slab = slabs_.size() < 4 ? 256 : slabs_.size() < 8 ? 1024 : 8192;  // a small engine stays small
  }
  Slab fresh = make_slab(slab);
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
