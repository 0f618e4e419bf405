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

// The slots a build aims at: `slots`, or one per 2 of the n live vertices
// when 0; at least 1, at most 2^30.
std::size_t slots_wanted(std::size_t slots, std::size_t n) {
  return std::min<std::size_t>(slots ? slots : std::max<std::size_t>(1, n / 2), std::size_t{1} << 30);
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

bool JumpGrid::check() const {
  // Every node but the root is some inner node's child once, the leaves'
  // slots tile [0, slot_count), and no path is deeper than max_depth.
  std::vector<int> parents(node_count, 0), depth(node_count, 1);
  std::vector<bool> slot_seen(slot_count, false);  // a bit per slot: each covered once
  std::size_t leaf_slots = 0;
  for (std::size_t i = 0; i < node_count; ++i) {
    const Node& node = nodes[i];
    if (node.k() < 1) return false;
    const std::uint64_t cells = std::uint64_t{node.k()} * node.k() * node.k();
    for (std::uint64_t j = 0; j < cells; ++j) {
      const std::uint64_t at = node.first + j;
      if (node.leaf()) {
        if (at >= slot_count || slot_seen[at]) return false;
        slot_seen[at] = true;
        ++leaf_slots;
      } else {
        if (at <= i || at >= node_count) return false;  // children come after their parent
        ++parents[at];
        depth[at] = depth[i] + 1;
        if (depth[at] > max_depth) return false;
      }
    }
  }
  if (node_count == 0 || parents[0] != 0) return false;
  for (std::size_t i = 1; i < node_count; ++i)
    if (parents[i] != 1) return false;
  return leaf_slots == slot_count;  // none twice, none outside: all of them
}

namespace {

// Calls body(v) for each live vertex id v in [1, verts.size()) outside
// `skip`, in pieces on the current arena's threads when parallel (for_range).
template <class Body>
void each_live_vertex(const StableArray<VertexRec>& verts, std::span<const IdRange> skip, bool parallel,
                      const Body& body) {
  for_range(verts.size(), parallel, [&](std::size_t begin, std::size_t end) {
    for_each_kept(std::max<std::size_t>(begin, 1), end, skip, [&](std::size_t from, std::size_t to) {
      for (std::size_t v = from; v < to; ++v)
        if (verts[v].multiplicity > 0) body(static_cast<VertexId>(v));
    });
  });
}

}  // namespace

JumpGrid JumpGrid::build(const StableArray<VertexRec>& verts, std::size_t slots, std::span<const IdRange> skip) {
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
  each_live_vertex(verts, skip, false, [&](VertexId v) {
    ids[n++] = v;
    const KPoint& p = verts[v].p;
    box.add(p.x(), p.y(), p.z());
  });
  const std::size_t want = slots_wanted(slots, n);
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
      const auto k = static_cast<std::uint32_t>(q == 0 ? g.lattice.res : leaf ? leaf_k(c) : inner_k(c));
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
    if (total > want && !last) {
      per_slot *= 1.25 * static_cast<double>(total) / static_cast<double>(want);
      continue;
    }
    g.node_count = nodes.size();
    g.nodes = std::make_unique<Node[]>(g.node_count);
    for (std::size_t i = 0; i < g.node_count; ++i) g.nodes[i] = nodes[i];
    g.slot_count = total;
    g.slots = std::make_unique<std::atomic<VertexId>[]>(g.slot_count);
    for (std::size_t s = 0; s < g.slot_count; ++s) g.set(s, no_vertex);
    each_live_vertex(verts, skip, false, [&](VertexId v) { g.set(g.slot_of(verts[v].p), v); });
    g.built_for = n;
    assert(g.check());
    return g;
  }
}

namespace {

// The live vertices' count and bounding box (in the current arena, isolated,
// when parallel).
struct Extent {
  BoundingBox box;
  std::size_t n = 0;
};
Extent live_extent(const StableArray<VertexRec>& verts, std::span<const IdRange> skip, bool parallel) {
  const std::size_t bound = verts.size();
  auto extent_of = [&](std::size_t begin, std::size_t end) {
    Extent e;
    for_each_kept(std::max<std::size_t>(begin, 1), end, skip, [&](std::size_t from, std::size_t to) {
      for (std::size_t v = from; v < to; ++v) {
        if (verts[v].multiplicity == 0) continue;
        ++e.n;
        const KPoint& p = verts[v].p;
        e.box.add(p.x(), p.y(), p.z());
      }
    });
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
  if (!parallel) return extent_of(0, bound);
  tbb::task_group_context own(tbb::task_group_context::isolated);  // for_range.hpp says why
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, bound, 1 << 14), Extent{},
      [&](const tbb::blocked_range<std::size_t>& r, Extent acc) { return join(acc, extent_of(r.begin(), r.end())); },
      join, own);
}

// A slot keeps the largest id it is offered: one thread going up the ids
// stores each; pieces in parallel keep the larger, whichever comes first.
void keep_largest(std::atomic<VertexId>& slot, VertexId v, bool parallel) {
  if (!parallel) {
    slot.store(v, std::memory_order_relaxed);
    return;
  }
  VertexId now = slot.load(std::memory_order_relaxed);
  while ((now == no_vertex || now < v) && !slot.compare_exchange_weak(now, v, std::memory_order_relaxed)) {
  }
}

// Counts one more vertex in `count`: from pieces in parallel, atomically.
void count_one(std::uint32_t& count, bool parallel) {
  if (parallel)
    std::atomic_ref<std::uint32_t>(count).fetch_add(1, std::memory_order_relaxed);
  else
    ++count;
}

// g's `slot_count` slots, allocated and all empty.
void allocate_empty_slots(JumpGrid& g, bool parallel) {
  g.slots.reset(new std::atomic<VertexId>[g.slot_count]);
  for_range(g.slot_count, parallel, [&](std::size_t begin, std::size_t end) {
    for (std::size_t s = begin; s < end; ++s) g.set(s, no_vertex);
  });
}

}  // namespace

JumpGrid JumpGrid::build_equal(const StableArray<VertexRec>& verts, std::size_t slots, bool parallel,
                               std::span<const IdRange> skip) {
  JumpGrid g;
  auto run = [&] {
    const Extent e = live_extent(verts, skip, parallel);
    const std::size_t want = slots_wanted(slots, e.n);
    g.lattice = BoxLattice(e.box.lo, e.box.hi, std::max(1, static_cast<int>(std::cbrt(static_cast<double>(want)))));
    const auto k = static_cast<std::uint32_t>(g.lattice.res);
    g.node_count = 1;
    g.nodes = std::make_unique<Node[]>(1);
    g.nodes[0] = {0, k | leaf_bit};
    g.slot_count = std::size_t{k} * k * k;
    allocate_empty_slots(g, parallel);
    // Each slot keeps its largest id (keep_largest), and its vertices are
    // counted, for `crowded` (scratch mapped for the build and unmapped after
    // it, as in build).
    StableArray<std::uint32_t> counts(g.slot_count);
    counts.grow(g.slot_count, false);  // zeros
    each_live_vertex(verts, skip, parallel, [&](VertexId v) {
      const std::size_t s = g.slot_of(verts[v].p);
      keep_largest(g.slots[s], v, parallel);
      count_one(counts[s], parallel);
    });
    // Crowded: 8 times the mean load, and more than crowded_slot (a grid at
    // its cap holds more than 2 vertices per slot everywhere).
    const double crowded_load = std::max<double>(crowded_slot, 8.0 * static_cast<double>(e.n) / static_cast<double>(g.slot_count));
    std::atomic<std::size_t> crowded{0};
    for_range(g.slot_count, parallel, [&](std::size_t begin, std::size_t end) {
      std::size_t here = 0;
      for (std::size_t s = begin; s < end; ++s)
        if (counts[s] > crowded_load) here += counts[s];
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

JumpGrid JumpGrid::build_split(const StableArray<VertexRec>& verts, std::size_t slots, std::size_t most,
                               bool parallel, std::span<const IdRange> skip) {
  const std::size_t bound = verts.size();
  JumpGrid g;
  auto run = [&] {
    const Extent e = live_extent(verts, skip, parallel);
    const std::size_t want = slots_wanted(slots, e.n);
    const std::size_t limit = std::min<std::size_t>(std::max(want, most), std::size_t{1} << 30);
    g.lattice = BoxLattice(e.box.lo, e.box.hi, std::max(1, static_cast<int>(std::cbrt(static_cast<double>(want)))));
    const auto k0 = static_cast<std::uint32_t>(g.lattice.res);
    const std::size_t roots = std::size_t{k0} * k0 * k0;
    // Scratch mapped for the build and unmapped after it (as in build): the
    // nodes (the root, then children after their parent; every leaf holds one
    // slot, the split ones' slots going to their first child, so the slots
    // never exceed the limit and the nodes twice that), each node's depth and
    // its vertices counted in the round that made it, each vertex's leaf.
    StableArray<Node> nodes(2 * std::max(limit, roots) + 2);
    StableArray<std::uint8_t> depth(2 * std::max(limit, roots) + 2);
    StableArray<std::uint32_t> count(2 * std::max(limit, roots) + 2);
    StableArray<std::uint32_t> leaf_of(bound + 1);
    nodes.grow(1 + roots, false);
    depth.grow(1 + roots, false);
    count.grow(1 + roots, false);  // zeros
    leaf_of.grow(bound, false);    // zeros: no leaf yet (node 0 is the root, never a leaf)
    nodes[0] = {1, k0};
    for (std::size_t i = 0; i < roots; ++i) {
      nodes[1 + i] = {static_cast<std::uint32_t>(i), 1 | leaf_bit};
      depth[1 + i] = 2;
    }
    std::size_t slot_total = roots;
    // The leaf holding p: slot_of's arithmetic, so the grid's slot_of(p) ends there.
    auto leaf_node = [&](const KPoint& p) {
      const double c[3] = {p.x(), p.y(), p.z()};
      double f[3];
      for (int a = 0; a < 3; ++a) f[a] = g.lattice.position(a, c[a]) / g.lattice.res;
      std::uint32_t n = 0;
      while (!nodes[n].leaf()) {
        const std::uint32_t k = nodes[n].k();
        const int x = sub_index(f[0], k), y = sub_index(f[1], k), z = sub_index(f[2], k);
        n = nodes[n].first + (static_cast<std::uint32_t>(z) * k + y) * k + x;
      }
      return n;
    };
    std::size_t round_begin = 1, round_end = 1 + roots;  // the leaves the last round made
    // A leaf is cut when it holds more than split_slot vertices and 4 times
    // the mean load (above 2 per slot when the cap binds).
    const double cut_above = std::max<double>(split_slot, 4.0 * static_cast<double>(e.n) / static_cast<double>(roots));
    for (;;) {
      // Each vertex whose leaf was cut (or that has none yet) finds its new
      // leaf, which counts it.
      each_live_vertex(verts, skip, parallel, [&](VertexId v) {
        if (leaf_of[v] != 0 && nodes[leaf_of[v]].leaf()) return;
        const std::uint32_t at = leaf_node(verts[v].p);
        leaf_of[v] = at;
        count_one(count[at], parallel);
      });
      // Cut the last round's crowded leaves, in node order, while the slots
      // fit the limit.
      const std::size_t next_begin = nodes.size();
      for (std::size_t i = round_begin; i < round_end; ++i) {
        if (count[i] <= cut_above || depth[i] >= max_depth) continue;
        // About 16 per child if they spread over the leaf (cut again if so,
        // 8 ways): a cluster far smaller than the leaf falls into one child,
        // and each cut spends few slots on the empty ones.
        auto k = static_cast<std::uint32_t>(
            std::clamp(std::round(std::cbrt(static_cast<double>(count[i]) / 16.0)), 2.0, 64.0));
        while (k > 2 && slot_total + std::size_t{k} * k * k - 1 > limit) --k;  // what fits
        const std::size_t cells = std::size_t{k} * k * k;
        if (slot_total + cells - 1 > limit) continue;
        const std::size_t first = nodes.grow(cells, false);
        depth.grow(cells, false);
        count.grow(cells, false);
        for (std::size_t j = 0; j < cells; ++j) {
          nodes[first + j] = {j == 0 ? nodes[i].first : static_cast<std::uint32_t>(slot_total++), 1 | leaf_bit};
          depth[first + j] = static_cast<std::uint8_t>(depth[i] + 1);
        }
        nodes[i] = {static_cast<std::uint32_t>(first), k};
      }
      if (nodes.size() == next_begin) break;  // no leaf cut: every vertex's leaf is final
      round_begin = next_begin;
      round_end = nodes.size();
    }
    g.node_count = nodes.size();
    g.nodes = std::make_unique<Node[]>(g.node_count);
    for (std::size_t i = 0; i < g.node_count; ++i) g.nodes[i] = nodes[i];
    g.slot_count = slot_total;
    allocate_empty_slots(g, parallel);
    // Each slot keeps its largest id, as in build_equal.
    each_live_vertex(verts, skip, parallel,
                     [&](VertexId v) { keep_largest(g.slots[nodes[leaf_of[v]].first], v, parallel); });
    g.built_for = e.n;
    assert(g.check());
  };
  if (parallel)
    tbb::this_task_arena::isolate(run);
  else
    run();
  return g;
}

}  // namespace pdt::detail
