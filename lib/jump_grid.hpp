// SPDX-License-Identifier: MIT
#pragma once
// Jump-and-walk start (paper §2.1, Mücke et al.), structured: a grid over
// the live vertices' bounding box remembers, per slot, the last vertex
// inserted there. Locating p starts at the vertex of p's slot (or of a filled
// slot near it), so walks stay short.
//
// The grid is a tree of grids so that it follows where the vertices are: the
// box is cut into res^3 equal nodes, and a node holding many vertices is cut
// again, k^3 ways, until a node (a leaf) holds few; a leaf is cut into k^3
// slots of about `per_slot` vertices each, chosen when the grid is built. A
// uniform grid would give a point set that fills a small part of its box (a
// scanned surface, points near a line) tens of vertices per slot where they
// are, and walks that many cells longer. For uniform points the tree is two
// levels: the root's grid, and leaves of 1, 8 or 27 slots (mostly 8). The
// engine builds only the root, as equal slots, unless the equal slots are
// crowded (a cluster): then the crowded ones are cut again where the
// vertices are (build_split; see grid_rebuild).
//
// Encoding: nodes[i] = {first, k | leaf_bit}: an inner node's children are
// nodes [first, first + k^3), a leaf's slots are slots [first, first + k^3);
// child or slot (x, y, z) of a node is at first + (z * k + y) * k + x. Node 0
// is the root, cut res x res x res by `lattice` over the bounding box.
// Invariant (check(), asserted after build and build_split): k >= 1; every
// node but the root is the child of exactly one inner node, numbered after
// it; the leaves' slot ranges tile [0, slot_count); depth <= max_depth.
//
// Slots are relaxed atomics: a slot may name a vertex that has since died or
// been recycled, so a reader checks the vertex (under its lock, in the engine)
// before using it. The tree itself never changes after build. Who regrows
// the grid: the kernel, each time the vertex count doubles, unless an engine
// drives the triangulation (then the engine does, with the world stopped; see
// Triangulation::Impl::grid_growth).
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "box_lattice.hpp"
#include "id_ranges.hpp"
#include "stable_array.hpp"
#include "storage.hpp"

namespace pdt::detail {

struct JumpGrid {
  static constexpr std::uint32_t leaf_bit = 0x80000000u;
  static constexpr int max_depth = 12;
  struct Node {
    std::uint32_t first;
    std::uint32_t k_leaf;  // k | leaf_bit for a leaf
    std::uint32_t k() const { return k_leaf & ~leaf_bit; }
    bool leaf() const { return (k_leaf & leaf_bit) != 0; }
  };
  BoxLattice lattice;  // the root's res^3 children over the vertices' bounding box
  std::unique_ptr<Node[]> nodes;
  std::unique_ptr<std::atomic<VertexId>[]> slots;
  std::size_t node_count = 0;
  std::size_t slot_count = 0;  // 0: no grid
  std::size_t built_for = 0;   // live vertices when it was built
  // build_equal: the live vertices in slots holding more than crowded_slot
  // of them, and 8 times the mean, when it was built (equal slots serve a
  // cluster badly); 0 for the other builds.
  static constexpr std::uint32_t crowded_slot = 16;
  std::size_t crowded = 0;

  // The cell of a k^3 grid that holds fraction f in [0, 1] along an axis, and
  // f's fraction within that cell.
  static int sub_index(double& f, std::uint32_t k) {
    const double t = f * k;
    const int i = std::min(static_cast<int>(t), static_cast<int>(k) - 1);
    f = std::min(std::max(t - i, 0.0), 1.0);
    return i;
  }
  // The path from the root to p's slot: node[d] and p's cell in it, cell[d],
  // for d < depth; node[depth - 1] is a leaf, and its cell is the slot.
  struct Path {
    std::uint32_t node[max_depth + 1];
    int cell[max_depth + 1][3];
    int depth = 0;
  };
  void path_of(const KPoint& p, Path& path) const {
    const double c[3] = {p.x(), p.y(), p.z()};
    double f[3];
    for (int a = 0; a < 3; ++a) f[a] = lattice.position(a, c[a]) / lattice.res;
    std::uint32_t n = 0;
    path.depth = 0;
    while (true) {
      const Node& node = nodes[n];
      const std::uint32_t k = node.k();
      int* cell = path.cell[path.depth];
      for (int a = 0; a < 3; ++a) cell[a] = sub_index(f[a], k);
      path.node[path.depth++] = n;
      const std::uint32_t next = node.first + (static_cast<std::uint32_t>(cell[2]) * k + cell[1]) * k + cell[0];
      if (node.leaf()) return;
      n = next;
    }
  }
  std::size_t slot_of(const KPoint& p) const {
    const double c[3] = {p.x(), p.y(), p.z()};
    double f[3];
    for (int a = 0; a < 3; ++a) f[a] = lattice.position(a, c[a]) / lattice.res;
    std::uint32_t n = 0;
    while (true) {
      const Node& node = nodes[n];
      const std::uint32_t k = node.k();
      const int x = sub_index(f[0], k), y = sub_index(f[1], k), z = sub_index(f[2], k);
      const std::uint32_t next = node.first + (static_cast<std::uint32_t>(z) * k + y) * k + x;
      if (node.leaf()) return next;
      n = next;
    }
  }
  VertexId get(std::size_t s) const { return slots[s].load(std::memory_order_relaxed); }
  void set(std::size_t s, VertexId v) { slots[s].store(v, std::memory_order_relaxed); }
  // The vertex of p's slot, else of the nearest filled slot within two shells
  // around it in its leaf, else of a filled slot in the nodes around p's
  // path, from the leaf up; no_vertex if none.
  VertexId lookup(const KPoint& p) const;

  // A grid over the live vertices of verts (ids 1..), with at most `slots`
  // slots when given (and about that many when the vertices are spread
  // evenly), else about 2 vertices per slot. Counts the vertices itself (the
  // triangulation's totals lag while engine workers hold deltas). The ids in
  // `skip` are not read (all free: Impl::released_ranges), here and in
  // build_equal and build_split.
  static JumpGrid build(const StableArray<VertexRec>& verts, std::size_t slots = 0,
                        std::span<const IdRange> skip = {});
  // One level of equal slots over the same box, as many as fit in `slots`
  // (about n / 2 when 0): for the engine, whose workers fill the domain
  // block by block, so that the vertices at a rebuild say little about where
  // the next ones go (a tree shaped by them made 2-worker walks 12% longer on
  // uniform points). A slot names the largest id of its vertices, as build's
  // would. parallel: in the current TBB arena, isolated (the engine builds it
  // with the world stopped, its other workers suspended and their threads
  // free); the same grid either way.
  static JumpGrid build_equal(const StableArray<VertexRec>& verts, std::size_t slots, bool parallel,
                              std::span<const IdRange> skip = {});
  // For an engine whose equal slots are crowded (a cluster): the same equal
  // slots as build_equal's, each a leaf of one slot, and then, round after
  // round, each leaf made in the last round that holds more than split_slot
  // vertices (and 4 times the mean load) cut into k^3 leaves (about 16
  // vertices each if they spread over it, so cut again, 8 ways; k smaller
  // where that does not fit), while the slots stay within `most` (at least
  // `slots`). Every round is a pass over the
  // vertices (in parallel when asked, as build_equal), so it costs about
  // build_equal's time per level the clusters need, where build's tree is
  // built on one thread; the same grid either way.
  static constexpr std::uint32_t split_slot = 8;
  static JumpGrid build_split(const StableArray<VertexRec>& verts, std::size_t slots, std::size_t most, bool parallel,
                              std::span<const IdRange> skip = {});
  // Bytes it holds.
  std::size_t bytes() const { return slot_count * sizeof(VertexId) + node_count * sizeof(Node); }
  // Whether a rebuild before the vertex count doubles may pay (WalkWatch):
  // a quarter more live vertices than a grid built for `built_for` of them.
  static bool grown_since(std::size_t built_for, std::size_t live) {
    return live >= built_for + std::max<std::size_t>(1024, built_for / 4);
  }
  bool grown_since_build(std::size_t live) const { return slot_count != 0 && grown_since(built_for, live); }
  // Whether the slots have come to name mostly dead vertices (removals): the
  // live vertices a quarter of those it was built for, and it was built for
  // more than a few (a rebuild for a small mesh costs as much as the slots
  // save).
  static bool shrunk_since(std::size_t built_for, std::size_t live) {
    return built_for >= min_shrunk_rebuild && 4 * live < built_for;
  }
  static constexpr std::size_t min_shrunk_rebuild = 4096;
  bool shrunk_since_build(std::size_t live) const { return slot_count != 0 && shrunk_since(built_for, live); }

  // The encoding's invariant (above), and depth <= max_depth.
  bool check() const;

 private:
  // A filled slot of node n's subtree, reading at most `budget` slots.
  VertexId any_in(std::uint32_t n, int& budget) const;
};

// Walks that stay long after a build say the vertices have moved since (a
// region filled after it: a cluster, a zone a refiner refines, the blocks one
// worker serves in turn), and the grid is rebuilt then instead of when the
// vertex count doubles (JumpGrid::grown_since bounds how often). One per
// context that inserts (its stats): long_walks looks once per `window`
// insertions, at the walks since its last look (an engine's rolled-back
// walks included). A rebuild it asked for that did not halve the walks (points
// on a sphere, whose cells span the ball, walk 160 steps from any start)
// disarms it until the next rebuild as the count doubles (rearm): on such a
// stream the early rebuilds cost the sequential kernel 7%. Invariant: steps
// and insertions are counts it has seen, so never above the context's (a
// count found smaller restarts the watch); asked > 0 only while armed.
struct WalkWatch {
  static constexpr std::uint64_t window = 1024;   // insertions between two looks
  static constexpr std::uint64_t long_walk = 20;  // steps per insertion that are long (uniform points: 6-7)
  std::uint64_t steps = 0, insertions = 0;        // the counts at the last look
  double asked = 0;                               // the mean walk when it last asked for a rebuild (0: not since rearm)
  bool armed = true;
  // Call only when a rebuild may follow (the grid has grown enough).
  bool long_walks(std::uint64_t walk_steps, std::uint64_t inserted) {
    if (inserted < insertions || walk_steps < steps) {
      steps = walk_steps, insertions = inserted;
      return false;
    }
    if (inserted - insertions < window) return false;
    const double mean = static_cast<double>(walk_steps - steps) / static_cast<double>(inserted - insertions);
    steps = walk_steps, insertions = inserted;
    if (!armed || mean <= long_walk) return false;
    if (asked > 0 && mean > asked / 2) {  // the last rebuild did not help
      armed = false;
      asked = 0;
      return false;
    }
    asked = mean;
    return true;
  }
  void rearm() { armed = true, asked = 0; }
};

}  // namespace pdt::detail
