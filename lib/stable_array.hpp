#pragma once
// StableArray<T>: a growable array whose elements never move.
//
// It reserves a large range of virtual addresses once (mmap, no backing store)
// and lets the OS commit pages as they are first touched, so growing never
// copies and never invalidates an index or a pointer, and it costs no memory
// for what is not used. That is what lets ids stay valid while storage grows,
// and lets worker threads read elements while another thread appends.
//
// Invariant: size() <= capacity(); elements [0, size()) were constructed.
// T must be trivially destructible (storage is released without destructors).
#include <sys/mman.h>

#include <atomic>
#include <cstddef>
#include <new>
#include <type_traits>

#include "pdt/error.hpp"

namespace pdt::detail {

template <class T>
class StableArray {
  static_assert(std::is_trivially_destructible_v<T>);

 public:
  explicit StableArray(std::size_t max_elements) : capacity_(max_elements) {
    void* p = ::mmap(nullptr, bytes(), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    data_ = static_cast<T*>(p);
  }
  ~StableArray() {
    if (data_) ::munmap(data_, bytes());
  }
  StableArray(const StableArray&) = delete;
  StableArray& operator=(const StableArray&) = delete;

  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  T* data() { return data_; }
  std::size_t size() const { return size_.load(std::memory_order_acquire); }
  std::size_t capacity() const { return capacity_; }

  // Appends `count` default-constructed elements and returns the index of the
  // first. Safe to call from several threads at once.
  std::size_t grow(std::size_t count) {
    std::size_t first = size_.fetch_add(count, std::memory_order_acq_rel);
    if (first + count > capacity_) {
      size_.fetch_sub(count, std::memory_order_acq_rel);
      throw std::bad_alloc();
    }
    for (std::size_t i = first; i < first + count; ++i) new (&data_[i]) T();
    return first;
  }
  // Makes size() at least n without constructing anything: for arrays whose
  // elements are all-zero when fresh (mmap'd pages are). Thread-safe.
  void ensure_size(std::size_t n) {
    if (n > capacity_) throw std::bad_alloc();
    std::size_t cur = size_.load(std::memory_order_acquire);
    while (cur < n && !size_.compare_exchange_weak(cur, n, std::memory_order_acq_rel)) {
    }
  }
  // Forgets every element; with release, also returns the committed pages to
  // the OS (without, a scratch array reused per operation keeps its pages warm).
  void clear(bool release = true) {
    std::size_t n = size_.exchange(0);
    if (n && release) ::madvise(data_, n * sizeof(T), MADV_DONTNEED);
  }

 private:
  std::size_t bytes() const { return capacity_ * sizeof(T); }
  T* data_ = nullptr;
  std::size_t capacity_;
  std::atomic<std::size_t> size_{0};
};

}  // namespace pdt::detail
