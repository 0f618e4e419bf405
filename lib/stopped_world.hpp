// SPDX-License-Identifier: MIT
#pragma once
// The stopped world: what cannot run under vertex locks (a change of
// dimension, an operation that escalated, the jump grid's regrowth, a recut
// of the blocks) runs while no other worker is inside an operation.
//
// Protocol (all seq_cst): a worker announces in_op[i] = true, then checks
// `stopped`; if it is set, the worker withdraws (in_op[i] = false) and
// suspends until restart() resumes it: it does not spin. A stopper takes the
// mutex, sets `stopped`, then waits until every other in_op is false (each is
// at most one operation away). So once try_stop returns true, no other worker
// is inside an operation or can enter one until restart().
// Invariants: stopped => the mutex is held by the stopper; a waiter is
// registered only while stopped (both under waiters_mutex_).
#include <atomic>
#include <coroutine>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace pdt::detail {

class StoppedWorld {
 public:
  // Room for every worker's handle in both lists, once: stopping, waiting
  // and restarting never allocate.
  explicit StoppedWorld(unsigned workers) : in_op_(std::make_unique<Flag[]>(workers)), workers_(workers) {
    waiters_.reserve(workers);
    resuming_.reserve(workers);
  }

  bool stopped() const { return stopped_.load(std::memory_order_seq_cst); }
  // Worker i enters an operation: false (and not entered) while the world is stopped.
  bool enter(unsigned i) {
    std::atomic<bool>& mine = in_op_[i].value;
    mine.store(true, std::memory_order_seq_cst);
    if (!stopped_.load(std::memory_order_seq_cst)) return true;
    mine.store(false, std::memory_order_seq_cst);
    return false;
  }
  void leave(unsigned i) { in_op_[i].value.store(false, std::memory_order_seq_cst); }

  // Registers h to be resumed (through `resume`) at the next restart; false
  // when the world is no longer stopped (then just go on).
  bool wait(std::coroutine_handle<> h) {
    std::lock_guard lock(waiters_mutex_);
    if (!stopped_.load(std::memory_order_seq_cst)) return false;
    waiters_.push_back(h);
    return true;
  }

  // Worker i (not inside an operation) stops the world: true when it now runs
  // alone; false when another worker holds the world (retry later).
  bool try_stop(unsigned i, std::unique_lock<std::mutex>& lock) {
    lock = std::unique_lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    {
      std::lock_guard w(waiters_mutex_);
      stopped_.store(true, std::memory_order_seq_cst);
    }
    for (unsigned k = 0; k < workers_; ++k)
      if (k != i)
        while (in_op_[k].value.load(std::memory_order_seq_cst)) std::this_thread::yield();
    return true;
  }
  // Restarts the world and resumes every waiter with resume(handle).
  // The waiters are resumed while the stopper still holds the world, so the
  // next stop cannot start (and reuse `resuming_`) before they are all on
  // their way; a worker that tries meanwhile just finds the world held.
  template <class Resume>
  void restart(std::unique_lock<std::mutex>& lock, Resume resume) {
    {
      std::lock_guard w(waiters_mutex_);
      stopped_.store(false, std::memory_order_seq_cst);
      resuming_.assign(waiters_.begin(), waiters_.end());  // within capacity
      waiters_.clear();
    }
    for (std::coroutine_handle<> h : resuming_) resume(h);
    resuming_.clear();
    lock.unlock();
  }

 private:
  struct alignas(64) Flag {
    std::atomic<bool> value{false};
  };
  std::unique_ptr<Flag[]> in_op_;
  unsigned workers_;
  std::mutex mutex_;
  std::atomic<bool> stopped_{false};
  std::mutex waiters_mutex_;
  std::vector<std::coroutine_handle<>> waiters_;
  std::vector<std::coroutine_handle<>> resuming_;  // restart's copy, under mutex_
};

}  // namespace pdt::detail
