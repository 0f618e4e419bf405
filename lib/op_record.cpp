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

namespace {

// Unique among the threads alive (the address of a thread-local object).
std::uintptr_t thread_token() {
  thread_local const char token = 0;
  return reinterpret_cast<std::uintptr_t>(&token);
}

// The record is about to be written whole: ask for its lines now, so that
// the next submission finds them here rather than in the worker that
// released the record.
void prefetch_for_writing(const OpRecord* op) {
  const char* p = reinterpret_cast<const char*>(op);
  for (std::size_t at = 0; at < sizeof(OpRecord); at += 64) __builtin_prefetch(p + at, 1);
  __builtin_prefetch(p + sizeof(OpRecord) - 1, 1);
}

}  // namespace

OpRecord* OpRecordPool::acquire() {
  std::uintptr_t owner = front_.owner.load(std::memory_order_relaxed);
  if (owner == 0 && front_.owner.compare_exchange_strong(owner, thread_token(), std::memory_order_relaxed))
    owner = thread_token();
  if (owner == thread_token()) return acquire_front();
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
  const Fresh fresh = fresh_records();
  if (fresh.first != fresh.last) {  // the rest to this thread's shard
    Shard& s = shards_[home];
    std::lock_guard lock(s.mutex);
    fresh.last->next.store(s.head, std::memory_order_relaxed);
    s.head = fresh.first->next.load(std::memory_order_relaxed);
  }
  return fresh.first;
}

OpRecord* OpRecordPool::acquire_front() {
  OpRecord* op = front_.head;
  if (!op) op = take_list();
  front_.head = op->next.load(std::memory_order_relaxed);
  if (front_.head) prefetch_for_writing(front_.head);
  return op;
}

OpRecord* OpRecordPool::take_list() {
  thread_local unsigned found_last = 0;
  for (unsigned k = 0; k < shards; ++k) {
    const unsigned at = (found_last + k) % shards;
    Shard& s = shards_[at];
    std::lock_guard lock(s.mutex);
    if (OpRecord* list = s.head) {
      s.head = nullptr;
      found_last = at;
      return list;
    }
  }
  return fresh_records().first;
}

OpRecordPool::Fresh OpRecordPool::fresh_records() {
  PDT_FAULT_POINT("op record slab");
  std::size_t count;
  {
    std::lock_guard lock(slab_mutex_);
    count = slabs_.size() < 4 ? 256 : 1024;  // a small engine stays small
  }
  Slab slab = make_slab(count);
  OpRecord* first = slab.get();
  for (std::size_t i = 0; i + 1 < count; ++i) first[i].next.store(&first[i + 1], std::memory_order_relaxed);
  std::lock_guard lock(slab_mutex_);
  slabs_.push_back(std::move(slab));  // may throw: the slab goes, nothing was handed out
  return {first, first + count - 1};
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
