// SPDX-License-Identifier: MIT
#pragma once
// BlockQueue: the operations waiting in one block. An intrusive
// multi-producer single-consumer queue (Vyukov's): pushing is one exchange and
// never allocates (the link lives in the OpRecord), so a submission or a
// rollback cannot fail here.
//
// The consumer is whichever worker holds the block's claim (Block::holder);
// the claim's acquire/release hands head_ over from one holder to the next.
// Invariant: the records reachable from head_ (stub_ excluded) are exactly
// those pushed and not popped, except that a push in progress (its exchange
// done, its link not yet stored) is not reachable yet: pop() then reports
// empty, and the pusher's wake-up (after its push) makes sure someone looks
// again.
#include <atomic>

#include "op_record.hpp"

namespace pdt::detail {

class BlockQueue {
 public:
  BlockQueue() { stub_.next.store(nullptr, std::memory_order_relaxed); }
  BlockQueue(const BlockQueue&) = delete;
  BlockQueue& operator=(const BlockQueue&) = delete;

  void push(OpRecord* op) {
    op->next.store(nullptr, std::memory_order_relaxed);
    OpRecord* prev = tail_.exchange(op, std::memory_order_acq_rel);
    prev->next.store(op, std::memory_order_release);
  }

  // Consumer only: op goes before every queued record, so the next pop (by
  // this holder or the block's next one) returns it. The producers touch
  // only tail_ and the last record's link, never head_.
  void push_front(OpRecord* op) {
    op->next.store(head_, std::memory_order_relaxed);
    head_ = op;
  }

  // Consumer only. nullptr when empty (or a push is in progress).
  OpRecord* pop() {
    OpRecord* head = head_;
    OpRecord* next = head->next.load(std::memory_order_acquire);
    if (head == &stub_) {
      if (!next) return nullptr;
      head_ = next;
      head = next;
      next = next->next.load(std::memory_order_acquire);
    }
    if (next) {
      head_ = next;
      // The record popped next, fetched while this one runs: the queue is
      // a chain of records the submitters wrote, each a cache miss to reach.
      __builtin_prefetch(next);
      return head;
    }
    if (head != tail_.load(std::memory_order_acquire)) return nullptr;  // a push in progress
    push(&stub_);
    next = head->next.load(std::memory_order_acquire);
    if (next) {
      head_ = next;
      return head;
    }
    return nullptr;
  }

 private:
  OpRecord stub_;
  std::atomic<OpRecord*> tail_{&stub_};
  OpRecord* head_ = &stub_;
};

}  // namespace pdt::detail
