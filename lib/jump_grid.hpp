// SPDX-License-Identifier: MIT
#pragma once
// Jump-and-walk start (paper §2.1, Mücke et al.), structured: a uniform grid
// over the live vertices' bounding box remembers, per slot, the last vertex
// inserted there. Locating p starts at the vertex of p's slot (or the nearest
// filled slot), so walks stay short.
//
// Slots are relaxed atomics: a slot may name a vertex that has since died or
// been recycled, so a reader checks the vertex (under its lock, in the engine)
// before using it. Who regrows the grid: the kernel, each time the vertex
// count doubles, unless an engine drives the triangulation (then the engine
// does, with the world stopped; see Triangulation::Impl::grid_growth).
#include <atomic>
#include <cstddef>
#include <memory>

#include "box_lattice.hpp"
#include "stable_array.hpp"
#include "storage.hpp"

namespace pdt::detail {

struct JumpGrid {
  BoxLattice lattice;  // res^3 slots over the vertices' bounding box
  std::unique_ptr<std::atomic<VertexId>[]> slots;
  std::size_t slot_count = 0;  // 0: no grid
  std::size_t built_for = 0;   // live vertices when it was built

  std::size_t slot_of(const KPoint& p) const {
    const int res = lattice.res;
    return (static_cast<std::size_t>(lattice.index(2, p.z())) * res + lattice.index(1, p.y())) * res +
           lattice.index(0, p.x());
  }
  VertexId get(std::size_t s) const { return slots[s].load(std::memory_order_relaxed); }
  void set(std::size_t s, VertexId v) { slots[s].store(v, std::memory_order_relaxed); }
  // The vertex of p's slot, else of the nearest filled slot within two shells
  // around it; no_vertex if none.
  VertexId lookup(const KPoint& p) const;

  // A grid over the live vertices of verts (ids 1..), with about `slots`
  // slots when given, else about 2 vertices per slot. Counts the vertices
  // itself (the triangulation's totals lag while engine workers hold deltas).
  static JumpGrid build(const StableArray<VertexRec>& verts, std::size_t slots = 0);
};

}  // namespace pdt::detail
