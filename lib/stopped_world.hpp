#pragma once
// The stopped world: operations that cannot run under vertex locks (those
// that change the dimension) and the jump grid's regrowth run while no other
// worker is inside an operation.
//
// Protocol (all seq_cst): a worker announces in_op[i] = true, then checks
// `stopped`; if set it withdraws and waits. A stopper takes the mutex, sets
// `stopped`, then waits until every other in_op is false. So once try_stop
// returns true, no other worker is inside an operation or can enter one
// until restart().
// Invariant: stopped => the mutex is held by the stopper.
#include <atomic>
#include <memory>
#include <mutex>
#include <thread>

namespace pdt::detail {

class StoppedWorld {
 public:
  explicit StoppedWorld(unsigned workers) : in_op_(std::make_unique<Flag[]>(workers)), workers_(workers) {}

  // Worker i enters an operation, waiting while the world is stopped.
  void enter(unsigned i) {
    std::atomic<bool>& mine = in_op_[i].value;
    mine.store(true, std::memory_order_seq_cst);
    while (stopped_.load(std::memory_order_seq_cst)) {
      mine.store(false, std::memory_order_seq_cst);
      while (stopped_.load(std::memory_order_acquire)) std::this_thread::yield();
      mine.store(true, std::memory_order_seq_cst);
    }
  }
  void leave(unsigned i) { in_op_[i].value.store(false, std::memory_order_seq_cst); }

  // Worker i (not inside an operation) stops the world: true when it now runs
  // alone; false when another worker holds the world (retry later).
  bool try_stop(unsigned i, std::unique_lock<std::mutex>& lock) {
    lock = std::unique_lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    stopped_.store(true, std::memory_order_seq_cst);
    for (unsigned k = 0; k < workers_; ++k)
      if (k != i)
        while (in_op_[k].value.load(std::memory_order_seq_cst)) std::this_thread::yield();
    return true;
  }
  void restart(std::unique_lock<std::mutex>& lock) {
    stopped_.store(false, std::memory_order_seq_cst);
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
};

}  // namespace pdt::detail
