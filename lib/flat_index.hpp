// SPDX-License-Identifier: MIT
#pragma once
// FlatIndex: the vertices of the lower-dimensional state by point, to find a
// duplicate: open addressing on a hash of the point's bits, linear probing,
// deletion by backward shift (no tombstones).
//
// Invariant: slots_.size() is 0 or a power of two at least twice count_
// (once reserve() was called for count_);
// every vertex is reachable from its home slot without crossing an empty one.
// reserve() is the only call that allocates, so a caller that reserves first
// can insert and erase without failing.
#include <cstdint>
#include <cstring>
#include <vector>

#include "mix64.hpp"
#include "open_addressing.hpp"
#include "predicates.hpp"
#include "stable_array.hpp"
#include "storage.hpp"

namespace pdt::detail {

class FlatIndex {
 public:
  using Vertices = StableArray<VertexRec>;

  // Room for n vertices without allocating again.
  void reserve(std::size_t n, const Vertices& verts) {
    std::size_t want = 16;
    while (want < 2 * n) want <<= 1;
    if (want <= slots_.size()) return;
    std::vector<VertexId> old(want, no_vertex);
    old.swap(slots_);
    count_ = 0;
    for (VertexId v : old)
      if (v != no_vertex) insert(v, verts);
  }
  void insert(VertexId v, const Vertices& verts) {
    std::size_t s = home(verts[v].p);
    while (slots_[s] != no_vertex) s = (s + 1) & mask();
    slots_[s] = v;
    ++count_;
  }
  VertexId find(const KPoint& p, const Vertices& verts) const {
    if (slots_.empty()) return no_vertex;
    for (std::size_t s = home(p);; s = (s + 1) & mask()) {
      const VertexId w = slots_[s];
      if (w == no_vertex) return no_vertex;
      if (verts[w].p == p) return w;
    }
  }
  void erase(VertexId v, const Vertices& verts) {
    std::size_t s = home(verts[v].p);
    while (slots_[s] != v) s = (s + 1) & mask();
    erase_by_backward_shift(slots_, s, no_vertex, [&](VertexId w) { return home(verts[w].p); });
    --count_;
  }
  // Empties it in time proportional to what it holds, not to the largest it
  // ever was: a removal's scratch triangulation clears it for every removal,
  // and after one removal with a large coplanar link each later one paid for
  // that link's table. A large table is given back (reserve() makes the next).
  void clear() {
    if (count_ == 0) return;  // every slot is empty already
    if (slots_.size() > 1024) {
      std::vector<VertexId>().swap(slots_);
    } else {
      slots_.assign(slots_.size(), no_vertex);
    }
    count_ = 0;
  }
  std::size_t size() const { return count_; }
  std::size_t table_size() const { return slots_.size(); }

 private:
  std::size_t mask() const { return slots_.size() - 1; }
  std::size_t home(const KPoint& p) const {
    std::uint64_t h = 0;
    const double c[3] = {p.x(), p.y(), p.z()};
    for (double d : c) {
      std::uint64_t bits;
      std::memcpy(&bits, &d, sizeof bits);
      h = mix64(h ^ bits);
    }
    return static_cast<std::size_t>(h) & mask();
  }
  std::vector<VertexId> slots_;
  std::size_t count_ = 0;
};

}  // namespace pdt::detail
