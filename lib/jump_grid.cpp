// SPDX-License-Identifier: MIT
#include "jump_grid.hpp"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstdlib>
#include <vector>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_reduce.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_group.h>

#include "for_range.hpp"

namespace pdt::detail {

namespace {

template <class Visit>
bool for_shell(const int at[3], int r, int k, Visit&& visit) {
  for (int dz = -r; dz <= r; ++dz)
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
        const int x = at[0] + dx, y = at[1] + dy, z = at[2] + dz;
        if (x < 0 || y < 0 || z < 0 || x >= k || y >= k || z >= k) continue;
        if (visit((static_cast<std::uint32_t>(z) * k + y) * k + x)) return true;
      }
  return false;
}

}  // namespace

VertexId JumpGrid::any_in(std::uint32_t n, int& budget) const {
  const Node& node = nodes[n];
  const std::uint32_t count = node.k() * node.k() * node.k();
  for (std::uint32_t i = 0; i < count && budget > 0; ++i) {
    VertexId v = no_vertex;
    if (node.leaf()) {
      --budget;
      v = get(node.first + i);
    } else {
      v = any_in(node.first + i, budget);
    }
    if (v != no_vertex) return v;
  }
  return no_vertex;
}

VertexId JumpGrid::lookup(const KPoint& p) const {
  VertexId v = get(slot_of(p));
  if (v != no_vertex) return v;
  Path path;
  path_of(p, path);
  const Node& leaf = nodes[path.node[path.depth - 1]];
  const int* at = path.cell[path.depth - 1];
  const int k = static_cast<int>(leaf.k());
  for (int r = 1; r <= std::min(2, k - 1); ++r)
    if (for_shell(at, r, k, [&](std::uint32_t i) { return (v = get(leaf.first + i)) != no_vertex; })) return v;
  // Up the path: any filled slot under the children around p's, nearest
  // level first, reading a bounded number of slots.
  int budget = 64;
  for (int d = path.depth - 2; d >= 0 && budget > 0; --d) {
    const Node& node = nodes[path.node[d]];
    const int kd = static_cast<int>(node.k());
    for (int r = 0; r <= std::min(2, kd - 1) && budget > 0; ++r)
      if (for_shell(path.cell[d], r, kd, [&](std::uint32_t i) {
            return budget > 0 && (v = any_in(node.first + i, budget)) != no_vertex;
          }))
        return v;
  }
  return no_vertex;
}

JumpGrid JumpGrid::build(const StableArray<VertexRec>& verts, std::size_t slots, bool even_floor, std::size_t most) {
  BoundingBox box;
  const std::size_t bound = verts.size();
  // The build's scratch is mapped for it and unmapped after it (StableArray),
  // so it goes back to the OS at once: malloc'd vectors of this size tend to
  // stay in the heap, and the process would keep the largest build's scratch
  // resident (10 MiB at 1M vertices).
  struct Pending {  // a node, its vertices ids[begin, end), its depth, its
    std::uint32_t begin, end;  // cube in the unit cube the root's lattice maps
    int depth;                 // the box to
    double origin[3], size;
  };
  const std::size_t max_nodes = 13 * bound / 2 + 64;  // 1 + depth * n / per_slot bounds it
  StableArray<VertexId> ids(bound + 1), ids2(bound + 1);
  StableArray<std::uint32_t> child(bound + 1);
  StableArray<Node> nodes(max_nodes);
  StableArray<Pending> queue(max_nodes);
  std::vector<std::uint32_t> offsets;
  ids.grow(bound, false);
  std::size_t n = 0;
  for (VertexId v = 1; v < bound; ++v) {
    if (verts[v].multiplicity == 0) continue;
    ids[n++] = v;
    const KPoint& p = verts[v].p;
    box.add(p.x(), p.y(), p.z());
  }
  const std::size_t want = std::min<std::size_t>(slots ? slots : std::max<std::size_t>(1, n / 2), std::size_t{1} << 30);
  // About `per_slot` vertices per slot, 2 unless the cap asks for more: few
  // slots are empty right after a build. Raised until the slots fit the cap.
  double per_slot = std::max(2.0, static_cast<double>(n) / static_cast<double>(want));
  ids2.grow(n, false);
  child.grow(n, false);
  for (int attempt = 0;; ++attempt) {
    // A node holding at most 16 * per_slot vertices is a leaf of 1, 8 or 27
    // slots; an inner node is cut so that its children hold about 8 *
    // per_slot. So for evenly spread vertices the root's children are leaves
    // (one pass over the vertices), and only a node twice as dense as its
    // surroundings is cut again. (A threshold of 8 * per_slot cut half the
    // uniform case's nodes again, and built 2.4x slower; 27 * per_slot gave
    // surfaces a third more vertices per slot.)
    const bool last = attempt == 8;  // then one slot: always fits
    auto leaf_k = [&](std::size_t c) {
      return last ? 1.0 : std::max(1.0, std::round(std::cbrt(static_cast<double>(c) / per_slot)));
    };
    auto is_leaf = [&](std::size_t c, int depth) {
      return last || static_cast<double>(c) <= 16 * per_slot || depth == max_depth - 1;
    };
    auto inner_k = [&](std::size_t c) {
      return std::clamp(std::round(std::cbrt(static_cast<double>(c) / (8 * per_slot))), 2.0, 1024.0);
    };
    JumpGrid g;
    const bool root_leaf = is_leaf(n, 0);
    g.lattice = BoxLattice(box.lo, box.hi, static_cast<int>(root_leaf ? leaf_k(n) : inner_k(n)));
    // even_floor: the root's leaves are cut at least as finely as the
    // vertices spread evenly over the box would cut them (a child the build
    // finds empty may fill later).
    const double root_cells = std::pow(static_cast<double>(g.lattice.res), 3);
    const double floor_k =
        even_floor && !last ? std::max(1.0, std::round(std::cbrt(static_cast<double>(n) / root_cells / per_slot))) : 1.0;
    // Breadth first, so that a node's children are consecutive; queue[i]
    // describes node i.
    nodes.clear(false);
    queue.clear(false);
    nodes.grow(1);
    queue[queue.grow(1)] = {0, static_cast<std::uint32_t>(n), 0, {0, 0, 0}, 1.0};
    std::size_t total = 0;
    for (std::size_t q = 0; q < queue.size(); ++q) {
      const Pending at = queue[q];
      const std::size_t c = at.end - at.begin;
      const bool leaf = q == 0 ? root_leaf : is_leaf(c, at.depth);
      const auto k = static_cast<std::uint32_t>(q == 0   ? g.lattice.res
                                                : leaf   ? std::max(leaf_k(c), at.depth == 1 ? floor_k : 1.0)
                                                         : inner_k(c));
      const std::uint32_t cells = k * k * k;
      if (leaf) {
        nodes[q] = {static_cast<std::uint32_t>(total), k | leaf_bit};
        total += cells;
        continue;
      }
      const auto first = static_cast<std::uint32_t>(nodes.grow(cells));
      queue.grow(cells);
      nodes[q] = {first, k};
      // Each vertex's child, then the range sorted by child (a counting sort
      // through ids2). The child is computed from the root, not by slot_of's
      // rescaling; where rounding differs, a vertex is counted in a
      // neighbouring child, which only shifts the counts.
      offsets.assign(cells + 1, 0);
      const double child_size = at.size / k, to_child = 1.0 / child_size, to_unit = 1.0 / g.lattice.res;
      for (std::size_t i = at.begin; i < at.end; ++i) {
        const KPoint& p = verts[ids[i]].p;
        const double c[3] = {p.x(), p.y(), p.z()};
        std::uint32_t xyz[3];
        for (int a = 0; a < 3; ++a) {
          const double f = (g.lattice.position(a, c[a]) * to_unit - at.origin[a]) * to_child;
          xyz[a] = static_cast<std::uint32_t>(std::clamp(f, 0.0, static_cast<double>(k - 1)));
        }
        child[i] = (xyz[2] * k + xyz[1]) * k + xyz[0];
        ++offsets[child[i] + 1];
      }
      for (std::uint32_t j = 0; j < cells; ++j) offsets[j + 1] += offsets[j];
      for (std::uint32_t j = 0; j < cells; ++j) {
        const std::uint32_t x = j % k, y = (j / k) % k, z = j / k / k;
        queue[first + j] = {at.begin + offsets[j], at.begin + offsets[j + 1], at.depth + 1,
                            {at.origin[0] + x * child_size, at.origin[1] + y * child_size, at.origin[2] + z * child_size},
                            child_size};
      }
      for (std::size_t i = at.begin; i < at.end; ++i) ids2[at.begin + offsets[child[i]]++] = ids[i];
      for (std::size_t i = at.begin; i < at.end; ++i) ids[i] = ids2[i];
    }
    const std::size_t limit = std::min<std::size_t>(std::max(want, most), std::size_t{1} << 30);
    if (total > limit && !last) {
      per_slot *= 1.25 * static_cast<double>(total) / static_cast<double>(limit);
      continue;
    }
    g.node_count = nodes.size();
    g.nodes = std::make_unique<Node[]>(g.node_count);
    for (std::size_t i = 0; i < g.node_count; ++i) g.nodes[i] = nodes[i];
    g.slot_count = total;
    g.slots = std::make_unique<std::atomic<VertexId>[]>(g.slot_count);
    for (std::size_t s = 0; s < g.slot_count; ++s) g.set(s, no_vertex);
    for (VertexId v = 1; v < bound; ++v)
      if (verts[v].multiplicity > 0) g.set(g.slot_of(verts[v].p), v);
    g.built_for = n;
#ifndef NDEBUG
    // The invariant: every node but the root is some inner node's child once,
    // and the leaves' slots tile [0, slot_count).
    std::vector<int> parents(g.node_count, 0);
    std::vector<std::uint32_t> leaf_slots;
    for (std::size_t i = 0; i < g.node_count; ++i) {
      const Node& node = g.nodes[i];
      assert(node.k() >= 1);
      const std::uint32_t cells = node.k() * node.k() * node.k();
      if (node.leaf()) {
        for (std::uint32_t j = 0; j < cells; ++j) leaf_slots.push_back(node.first + j);
      } else {
        for (std::uint32_t j = 0; j < cells; ++j) ++parents[node.first + j];
      }
    }
    assert(parents[0] == 0);
    for (std::size_t i = 1; i < g.node_count; ++i) assert(parents[i] == 1);
    std::sort(leaf_slots.begin(), leaf_slots.end());
    for (std::size_t s = 0; s < leaf_slots.size(); ++s) assert(leaf_slots[s] == s);
    assert(leaf_slots.size() == g.slot_count);
#endif
    return g;
  }
}

JumpGrid JumpGrid::build_equal(const StableArray<VertexRec>& verts, std::size_t slots, bool parallel) {
  const std::size_t bound = verts.size();
  struct Extent {
    BoundingBox box;
    std::size_t n = 0;
  };
  // Over ids [begin, end): what a pass adds up, and the slot each live vertex marks.
  auto extent_of = [&](std::size_t begin, std::size_t end) {
    Extent e;
    for (std::size_t v = std::max<std::size_t>(begin, 1); v < end; ++v) {
      if (verts[v].multiplicity == 0) continue;
      ++e.n;
      const KPoint& p = verts[v].p;
      e.box.add(p.x(), p.y(), p.z());
    }
    return e;
  };
  auto join = [](Extent a, const Extent& b) {
    a.n += b.n;
    for (int i = 0; i < 3; ++i) {
      a.box.lo[i] = std::min(a.box.lo[i], b.box.lo[i]);
      a.box.hi[i] = std::max(a.box.hi[i], b.box.hi[i]);
    }
    return a;
  };
  JumpGrid g;
  auto run = [&] {
    tbb::task_group_context own(tbb::task_group_context::isolated);  // for_range.hpp says why
    const Extent e = parallel ? tbb::parallel_reduce(
                                    tbb::blocked_range<std::size_t>(0, bound, 1 << 14), Extent{},
                                    [&](const tbb::blocked_range<std::size_t>& r, Extent acc) {
                                      return join(acc, extent_of(r.begin(), r.end()));
                                    },
                                    join, own)
                              : extent_of(0, bound);
    const std::size_t want = std::min<std::size_t>(slots ? slots : std::max<std::size_t>(1, e.n / 2), std::size_t{1} << 30);
    g.lattice = BoxLattice(e.box.lo, e.box.hi, std::max(1, static_cast<int>(std::cbrt(static_cast<double>(want)))));
    const auto k = static_cast<std::uint32_t>(g.lattice.res);
    g.node_count = 1;
    g.nodes = std::make_unique<Node[]>(1);
    g.nodes[0] = {0, k | leaf_bit};
    g.slot_count = std::size_t{k} * k * k;
    g.slots.reset(new std::atomic<VertexId>[g.slot_count]);
    for_range(g.slot_count, parallel, [&](std::size_t begin, std::size_t end) {
      for (std::size_t s = begin; s < end; ++s) g.set(s, no_vertex);
    });
    // Each slot keeps its largest id: one thread going up the ids stores
    // each; pieces in parallel keep the larger, whichever comes first. And
    // each slot's vertices are counted, for `crowded` (scratch mapped for
    // the build and unmapped after it, as in build).
    StableArray<std::uint32_t> counts(g.slot_count);
    counts.grow(g.slot_count, false);  // zeros
    for_range(bound, parallel, [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = std::max<std::size_t>(begin, 1); v < end; ++v) {
        if (verts[v].multiplicity == 0) continue;
        const std::size_t s = g.slot_of(verts[v].p);
        std::atomic<VertexId>& slot = g.slots[s];
        if (!parallel) {
          slot.store(static_cast<VertexId>(v), std::memory_order_relaxed);
          ++counts[s];
          continue;
        }
        std::atomic_ref<std::uint32_t>(counts[s]).fetch_add(1, std::memory_order_relaxed);
        VertexId now = slot.load(std::memory_order_relaxed);
        while ((now == no_vertex || now < v) &&
               !slot.compare_exchange_weak(now, static_cast<VertexId>(v), std::memory_order_relaxed)) {
        }
      }
    });
    std::atomic<std::size_t> crowded{0};
    for_range(g.slot_count, parallel, [&](std::size_t begin, std::size_t end) {
      std::size_t here = 0;
      for (std::size_t s = begin; s < end; ++s)
        if (counts[s] > crowded_slot) here += counts[s];
      crowded.fetch_add(here, std::memory_order_relaxed);
    });
    g.built_for = e.n;
    g.crowded = crowded.load(std::memory_order_relaxed);
  };
  if (parallel)
    tbb::this_task_arena::isolate(run);
  else
    run();
  return g;
}

}  // namespace pdt::detail
