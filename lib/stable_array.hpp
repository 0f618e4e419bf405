// SPDX-License-Identifier: MIT
#pragma once
// StableArray<T>: a growable array whose elements never move, in two builds
// (CMake option PDT_ALLOCATOR), compared by the benchmarks:
//
//  pool (default): one large range of virtual addresses is reserved once
//    (mmap, no backing store) and the OS commits pages as they are first
//    touched. Indexing is one add; the kernel's per-thread pools carve it into
//    chunks of 12 pages (cells) and 3 pages (vertices), as in paper §3.2.
//  mimalloc: the elements live in fixed-size chunks allocated from mimalloc's
//    thread-local heap of the thread that grows the array (so a worker's
//    cells come from its own heap); a chunk table maps an index to its chunk.
//    Indexing is one extra dependent load.
//
// Either way growing never copies and never invalidates an index or a
// pointer, so ids stay valid while storage grows and worker threads can read
// elements while another thread appends.
//
// Invariant: size() <= capacity(); elements [0, size()) were constructed by
// grow(). ensure_size() extends the size without constructing: its users
// (the cell marks) never read an element before writing it. clear(false)
// keeps the memory, and its old contents, for reuse; truncate() and zero()
// leave what they drop all-zero, as fresh memory.
// T must be trivially destructible (storage is released without destructors).
#include <sys/mman.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

#include "huge_pages.hpp"

#ifdef PDT_USE_MIMALLOC
#include <mimalloc.h>
#endif

namespace pdt::detail {

// Makes [p, p + bytes) all-zero: the whole pages inside it go back to the OS
// (they read as zero when touched again), the bytes on the pages it shares
// with its neighbours are cleared in place. Where the OS refuses the advice
// (a huge-page mapping), the pages are cleared in place too.
inline void zero_and_release(void* p, std::size_t bytes) {
  if (bytes == 0) return;
  constexpr std::uintptr_t page = 4096;
  const auto from = reinterpret_cast<std::uintptr_t>(p), to = from + bytes;
  const std::uintptr_t inner_from = (from + page - 1) & ~(page - 1), inner_to = to & ~(page - 1);
  if (inner_from >= inner_to) {
    std::memset(p, 0, bytes);
    return;
  }
  std::memset(p, 0, inner_from - from);
  std::memset(reinterpret_cast<void*>(inner_to), 0, to - inner_to);
  if (::madvise(reinterpret_cast<void*>(inner_from), inner_to - inner_from, MADV_DONTNEED) != 0)
    std::memset(reinterpret_cast<void*>(inner_from), 0, inner_to - inner_from);
}

#ifndef PDT_USE_MIMALLOC

template <class T>
class StableArray {
  static_assert(std::is_trivially_destructible_v<T>);

 public:
  // huge_pages: the array may grow large; then, if huge_pages_advised()
  // (PDT_HUGE_PAGES=1), ask for transparent huge pages (advice only; the
  // kernel may ignore it) past the array's first 4 MiB. An array that grows large then
  // takes one fault and one TLB entry per 2 MiB instead of per 4 KiB, while a
  // small one stays on 4 KiB pages: a huge page would cost it 2 MiB of
  // memory however little it holds (a program with a hundred small
  // triangulations would hold 600 MiB).
  explicit StableArray(std::size_t max_elements, bool huge_pages = false) : capacity_(max_elements) {
    [[maybe_unused]] const bool advise = huge_pages && huge_pages_advised();  // may throw: before the mapping
    void* p = ::mmap(nullptr, bytes(), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    data_ = static_cast<T*>(p);
#ifdef MADV_HUGEPAGE
    if (advise) {
      constexpr std::uintptr_t small_part = std::uintptr_t{4} << 20, huge_page = std::uintptr_t{2} << 20;
      const auto base = reinterpret_cast<std::uintptr_t>(p);
      const std::uintptr_t from = (base + small_part + huge_page - 1) & ~(huge_page - 1);
      if (from < base + bytes()) ::madvise(reinterpret_cast<void*>(from), base + bytes() - from, MADV_HUGEPAGE);
    }
#endif
  }
  ~StableArray() {
    if (data_) ::munmap(data_, bytes());
  }
  StableArray(const StableArray&) = delete;
  StableArray& operator=(const StableArray&) = delete;

  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  std::size_t size() const { return size_.load(std::memory_order_acquire); }
  std::size_t capacity() const { return capacity_; }

  // Appends `count` elements and returns the index of the first. Safe to call
  // from several threads at once. construct = false leaves them as fresh
  // memory, all-zero unless clear(false) recycled it: the size grows before
  // the elements exist, so a thread that may touch an element it found below
  // size() (the engine's random vertex probes lock it) must not race with a
  // constructor that resets it.
  std::size_t grow(std::size_t count, bool construct = true) {
    std::size_t first = size_.fetch_add(count, std::memory_order_acq_rel);
    if (first + count > capacity_) {
      size_.fetch_sub(count, std::memory_order_acq_rel);
      throw std::bad_alloc();
    }
    if (construct)
      for (std::size_t i = first; i < first + count; ++i) new (&data_[i]) T();
    return first;
  }
  // Commits the pages holding elements [from, to) for writing, keeping what
  // they hold: one system call for a chunk of fresh elements instead of a
  // fault per page, and a page first read (mapped to the kernel's shared zero
  // page) and then written costs a second fault and, with other threads
  // running, a TLB shootdown across CPUs (the cell tags, whose first access
  // reads the incarnation). Advice only: a kernel without
  // MADV_POPULATE_WRITE (before Linux 5.14) faults the pages in as before.
  void populate(std::size_t from, std::size_t to) {
#ifdef MADV_POPULATE_WRITE
    from = std::max(from, kept_);  // below kept_ the pages are committed already
    if (from >= to) return;
    constexpr std::uintptr_t page = 4096;
    const auto begin = reinterpret_cast<std::uintptr_t>(data_ + from) & ~(page - 1);
    const auto end = reinterpret_cast<std::uintptr_t>(data_ + to);
    ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_POPULATE_WRITE);
#else
    (void)from;
    (void)to;
#endif
  }
  // Makes size() at least n without constructing anything. Thread-safe.
  void ensure_size(std::size_t n) {
    if (n > capacity_) throw std::bad_alloc();
    std::size_t cur = size_.load(std::memory_order_acquire);
    while (cur < n && !size_.compare_exchange_weak(cur, n, std::memory_order_acq_rel)) {
    }
  }
  // Elements [from, to) (below size()) become all-zero, as fresh memory
  // reads, their whole pages returned to the OS. Nothing else may touch them
  // meanwhile.
  void zero(std::size_t from, std::size_t to) { zero_and_release(data_ + from, (to - from) * sizeof(T)); }
  // Drops the elements from n on (n <= size()): zero(n, size()), then the
  // size is n, so that growing again finds fresh memory. Single-threaded:
  // nothing else may use the array meanwhile.
  void truncate(std::size_t n) {
    const std::size_t old = size();
    if (n >= old) return;
    zero(n, old);
    size_.store(n, std::memory_order_release);
    kept_ = std::min(kept_, n);
  }
  // Forgets every element; with release, also returns the committed pages to
  // the OS (without, a scratch array reused per operation keeps its pages warm,
  // and populate skips them: a removal's small triangulation, cleared for each
  // removal, made three page-table walks per removal otherwise).
  void clear(bool release = true) {
    std::size_t n = size_.exchange(0);
    if (release) {
      if (n) ::madvise(data_, n * sizeof(T), MADV_DONTNEED);
      kept_ = 0;
    } else {
      kept_ = std::max(kept_, n);
    }
  }

 private:
  std::size_t bytes() const { return capacity_ * sizeof(T); }
  T* data_ = nullptr;
  std::size_t capacity_;
  std::atomic<std::size_t> size_{0};
  // Elements [0, kept_) lie on pages that an earlier use committed and a
  // clear(false) kept (populate is advice, so a wrong kept_ could only cost
  // faults, never correctness). Written by clear() alone, which runs with no
  // grow() or populate() beside it.
  std::size_t kept_ = 0;
};

#else  // PDT_USE_MIMALLOC

template <class T>
class StableArray {
  static_assert(std::is_trivially_destructible_v<T>);
  static constexpr std::size_t chunk_bits = 11;  // 2048 elements per chunk
  static constexpr std::size_t chunk_elems = std::size_t{1} << chunk_bits;

 public:
  // huge_pages: mimalloc's choice; PDT_HUGE_PAGES is still checked, so that a
  // bad value is refused in both builds alike.
  explicit StableArray(std::size_t max_elements, bool huge_pages = false)
      : capacity_(max_elements), table_size_((max_elements + chunk_elems - 1) / chunk_elems) {
    if (huge_pages) (void)huge_pages_advised();  // may throw: before the mapping
    // The table itself is reserved like the pool build's storage: untouched
    // entries cost nothing and read as null.
    void* p = ::mmap(nullptr, table_bytes(), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    table_ = static_cast<std::atomic<T*>*>(p);
  }
  ~StableArray() {
    release_chunks();
    if (table_) ::munmap(table_, table_bytes());
  }
  StableArray(const StableArray&) = delete;
  StableArray& operator=(const StableArray&) = delete;

  // Acquire: pairs with the CAS that published the chunk, so its zeroed
  // contents are visible to a thread that found the index below size().
  T& operator[](std::size_t i) { return table_[i >> chunk_bits].load(std::memory_order_acquire)[i & (chunk_elems - 1)]; }
  const T& operator[](std::size_t i) const {
    return table_[i >> chunk_bits].load(std::memory_order_acquire)[i & (chunk_elems - 1)];
  }
  std::size_t size() const { return size_.load(std::memory_order_acquire); }
  std::size_t capacity() const { return capacity_; }

  // As in the pool build, except that the chunks must exist before the new
  // size is published (another thread may index anything below size()): claim
  // [cur, cur + count) by CAS only after covering it.
  std::size_t grow(std::size_t count, bool construct = true) {
    std::size_t first = size_.load(std::memory_order_acquire);
    do {
      if (first + count > capacity_) throw std::bad_alloc();
      cover(first, first + count);
    } while (!size_.compare_exchange_weak(first, first + count, std::memory_order_acq_rel));
    if (construct)
      for (std::size_t i = first; i < first + count; ++i) new (&(*this)[i]) T();
    return first;
  }
  void ensure_size(std::size_t n) {
    if (n > capacity_) throw std::bad_alloc();
    std::size_t cur = size_.load(std::memory_order_acquire);
    if (cur >= n) return;
    cover(cur, n);
    while (cur < n && !size_.compare_exchange_weak(cur, n, std::memory_order_acq_rel)) {
    }
  }
  void clear(bool release = true) {
    size_.exchange(0);
    if (release) release_chunks();
  }
  void populate(std::size_t, std::size_t) {}  // mimalloc's chunks: its own choice
  // As in the pool build: the pages inside each chunk's part go back to the
  // OS; truncate also frees the chunks wholly past n.
  void zero(std::size_t from, std::size_t to) {
    while (from < to) {
      const std::size_t end = std::min(to, ((from >> chunk_bits) + 1) << chunk_bits);
      zero_and_release(&(*this)[from], (end - from) * sizeof(T));
      from = end;
    }
  }
  void truncate(std::size_t n) {
    const std::size_t old = size();
    if (n >= old) return;
    const std::size_t kept_chunks = (n + chunk_elems - 1) >> chunk_bits;
    zero(n, std::min(old, kept_chunks << chunk_bits));
    for (std::size_t c = kept_chunks; c < table_size_; ++c)
      if (T* p = table_[c].exchange(nullptr, std::memory_order_relaxed)) mi_free(p);
    size_.store(n, std::memory_order_release);
  }

 private:
  std::size_t table_bytes() const { return table_size_ * sizeof(std::atomic<T*>); }
  // Allocates the chunks holding [from, to) that do not exist yet, zeroed, on
  // the calling thread's mimalloc heap. Two threads racing for one chunk: the
  // loser frees its copy.
  void cover(std::size_t from, std::size_t to) {
    if (from >= to) return;
    for (std::size_t c = from >> chunk_bits; c <= (to - 1) >> chunk_bits; ++c) {
      if (table_[c].load(std::memory_order_acquire)) continue;
      T* fresh = static_cast<T*>(mi_zalloc_aligned(chunk_elems * sizeof(T), alignof(T) < 64 ? 64 : alignof(T)));
      if (!fresh) throw std::bad_alloc();
      T* expected = nullptr;
      if (!table_[c].compare_exchange_strong(expected, fresh, std::memory_order_acq_rel)) mi_free(fresh);
    }
  }
  void release_chunks() {
    for (std::size_t c = 0; c < table_size_; ++c)
      if (T* p = table_[c].exchange(nullptr, std::memory_order_relaxed)) mi_free(p);
  }
  std::size_t capacity_;
  std::size_t table_size_;
  std::atomic<T*>* table_ = nullptr;
  std::atomic<std::size_t> size_{0};
};

#endif

}  // namespace pdt::detail
