// SPDX-License-Identifier: MIT
#pragma once
// RawArray<T>: storage for n objects of T that nothing has written yet, for
// the large arrays a batch fills in a parallel loop (its sorted points, its
// order, its tickets' slots). std::vector's value-initialization zeroes them
// on the allocating thread first, which also takes every page fault there
// (1M points: 80 MB, on one thread before any parallel loop starts); here
// each page is first touched by the thread that fills it.
// T is an implicit-lifetime type (an aggregate, or trivially constructible)
// and trivially destructible, so the objects exist as soon as the storage
// does; invariant: the owner writes an element before it reads it.
#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>

namespace pdt::detail {

struct RawFree {
  void operator()(void* p) const noexcept { ::operator delete(p); }
};

template <class T>
using RawArray = std::unique_ptr<T[], RawFree>;

// Throws std::bad_alloc.
template <class T>
RawArray<T> make_raw_array(std::size_t n) {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T> &&
                alignof(T) <= __STDCPP_DEFAULT_NEW_ALIGNMENT__);
  return RawArray<T>(static_cast<T*>(::operator new(n * sizeof(T))));
}

}  // namespace pdt::detail
