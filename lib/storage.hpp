// SPDX-License-Identifier: MIT
#pragma once
// The records a triangulation is made of, and how they are encoded.
//
//   CellRec.v[i]  vertex i of the cell. Vertex 0 is the infinite vertex.
//   CellRec.n[i]  4 * d + j: cell d shares this cell's facet i (the facet
//                 opposite v[i]) and that facet is d's facet j. So following an
//                 adjacency and finding the mirror facet is one load.
//                 A free cell has v[0] == no_vertex (a freed one: every slot)
//                 and n[0] == the next free cell of the pool that owns it.
//   VertexRec     point, one incident cell, multiplicity, lock word, stamp.
//                 A free vertex has multiplicity 0 and cell == the next free
//                 vertex of its pool (while dimension < 3, a live vertex's cell
//                 is its position in the flat list instead).
//
// Facet i of a cell lists its vertices in facet_vertex[i] order, so that every
// facet is seen with the same handedness from its cell: two cells sharing a
// facet list it in opposite cyclic orders.
#include <atomic>
#include <cstdint>

#include "pdt/triangulation.hpp"
#include "predicates.hpp"

namespace pdt::detail {

struct CellRec {
  VertexId v[4];
  std::uint32_t n[4];
};

struct VertexRec {
  KPoint p;
  CellId cell = no_cell;
  std::uint32_t multiplicity = 0;
  // 0 free, k > 0 held shared by k readers, -(owner) held exclusively by the
  // context whose id is owner (vertex_locks.cpp).
  std::atomic<std::int32_t> lock{0};
  // Scratch of the one operation that holds this vertex exclusively (the
  // sequential context holds everything): cone_from_vertex numbers the
  // boundary's vertices here, remove_3d the link's (Impl::small_id).
  // Meaningless between operations; it fills what would be padding, so the
  // record stays 48 bytes.
  std::uint32_t scratch = 0;
  // Unique per vertex incarnation; 0 when free. Atomic so that a thread
  // submitting a removal can read it without a lock: it is stored (release)
  // after p on allocation, cleared on release.
  std::atomic<std::uint64_t> stamp{0};
};

inline constexpr int facet_vertex[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};

inline constexpr std::uint32_t no_index = 0xFFFFFFFFu;

// A context's singly linked free list of cell or vertex ids threaded through
// the records (CellRec.n[0], VertexRec.cell), pushed and popped at the head,
// with S the segment size of its kind (pools.cpp). count == 0 <=> head ==
// no_index; the last id's next is no_index. count < 2S: at 2S the oldest S
// ids, from `mark` on, go to the triangulation's spare segments. mark is the
// id with exactly S ids from it to the end (itself included) when count >= S,
// else no_index; boundary is the id just before mark when count >= S + 1,
// else no_index.
struct FreeList {
  std::uint32_t head = no_index;
  std::uint32_t mark = no_index;
  std::uint32_t boundary = no_index;
  std::size_t count = 0;
};

// Free ids no context keeps: segments of exactly S ids each, stacked. A
// segment is a FreeList chain; its first id links to the next segment's
// first (CellRec.n[1], VertexRec.scratch: free records do not use them).
struct SpareSegments {
  // Written under the triangulation's spare_mutex; read without it only to
  // skip taking the mutex when there is nothing to take.
  std::atomic<std::uint32_t> head{no_index};
};

// What an operation of the kernel ended with.
enum class OpStatus {
  done,
  rollback,     // met a lock held by another thread; nothing was changed
  needs_global  // would change the dimension: must run with the world stopped
};

}  // namespace pdt::detail
