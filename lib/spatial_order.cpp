// SPDX-License-Identifier: MIT
#ifndef CGAL_LINKED_WITH_TBB
#define CGAL_LINKED_WITH_TBB 1  // CGAL's Parallel_tag sort; pdt links oneTBB
#endif
#include "spatial_order.hpp"

#include <sys/mman.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_group.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <mutex>
#include <new>
#include <numeric>
#include <utility>

#include "box_lattice.hpp"
#include "for_range.hpp"
#include "mix64.hpp"
#include "raw_array.hpp"

namespace pdt::detail {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;

// Index -> CGAL point, read from the caller's points (no copy of the batch).
struct IndexToPoint {
  using key_type = std::uint32_t;
  using value_type = Kernel::Point_3;
  using reference = value_type;
  using category = boost::readable_property_map_tag;
  const Point3* points;
  friend value_type get(const IndexToPoint& m, std::uint32_t i) {
    const Point3& p = m.points[i];
    return {p.x, p.y, p.z};
  }
};

std::vector<std::uint32_t> cgal_order(std::span<const Point3> points, bool parallel) {
  std::vector<std::uint32_t> order(points.size());
  std::iota(order.begin(), order.end(), std::uint32_t{0});
  using Traits = CGAL::Spatial_sort_traits_adapter_3<Kernel, IndexToPoint>;
  Traits traits(IndexToPoint{points.data()});
  if (parallel)
    CGAL::spatial_sort<CGAL::Parallel_tag>(order.begin(), order.end(), traits);
  else
    CGAL::spatial_sort<CGAL::Sequential_tag>(order.begin(), order.end(), traits);
  return order;
}

constexpr int key_bits = 21;  // per axis: 63-bit keys

// The low 21 bits of v, spread to every third bit (bit i to bit 3i).
constexpr std::uint64_t spread3(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// The lattice point's Morton code: bit L of axis a at bit 3L + 2 - a, so that
// its 3-bit digit at level L is (x0, x1, x2)'s bits L.
constexpr std::uint64_t morton_code(const std::uint32_t x[3]) {
  return spread3(x[0]) << 2 | spread3(x[1]) << 1 | spread3(x[2]);
}

// The position of the lattice point x on the 3D Hilbert curve of order
// key_bits: Skilling's transform of the axes ("Programming the Hilbert curve",
// AIP Conf. Proc. 707, 2004), then the transposed bits interleaved. The
// definition of the order; the batches compute it with HilbertMachine below.
constexpr std::uint64_t hilbert_key(std::array<std::uint32_t, 3> x) {
  for (std::uint32_t q = 1u << (key_bits - 1); q > 1; q >>= 1) {
    const std::uint32_t p = q - 1;
    for (int i = 0; i < 3; ++i) {  // without branches: the bits are random
      const std::uint32_t set = 0u - ((x[i] & q) != 0);  // all ones if bit q of x[i] is set
      const std::uint32_t t = (x[0] ^ x[i]) & p & ~set;  // else: exchange the low bits of x[0] and x[i]
      x[0] ^= (p & set) | t;                              // if set: invert the low bits of x[0]
      x[i] ^= t;
    }
  }
  x[1] ^= x[0];
  x[2] ^= x[1];
  std::uint32_t t = 0;
  for (std::uint32_t q = 1u << (key_bits - 1); q > 1; q >>= 1) t ^= (q - 1) & (0u - ((x[2] & q) != 0));
  for (int i = 0; i < 3; ++i) x[i] ^= t;
  return morton_code(x.data());
}

// hilbert_key as a finite-state machine over the Morton code's digits, from
// the top: the key's digit at level L depends only on the digits at L and
// above, through the curve's orientation there (a state). One step reads two
// levels (a 6-bit digit) and gives the key's 6 bits there and the next state,
// from a table (11 loads a key where Skilling's transform does 20 levels of
// work: 1M keys on one thread, four interleaved, 30 -> 12 ns each).
//
// The tables are derived from hilbert_key itself, so they cannot drift from
// it: a prefix's state is named by the order in which the curve visits the 8
// subcubes after it (what hilbert_key gives each next digit: on this curve the
// order fixes the orientation, 24 of them), and each state's step is read off
// hilbert_key for a representative prefix. Built once per process (about
// 1,700 calls of hilbert_key: well under a millisecond; at compile time it
// exceeded Clang's constexpr step limit); checked against hilbert_key on 520
// points in debug builds, and for every key a batch computes.
// Encoding: entry = next state << 6 | key bits (3 in `first`, 6 in `pair`).
struct HilbertMachine {
  static constexpr int max_states = 48;  // orientations of the cube (24 on this curve)
  std::uint16_t first[max_states * 8]{};  // one level: the top one (21 levels = 1 + 10 pairs)
  std::uint16_t pair[max_states * 64]{};
  int states = 0;
};

HilbertMachine make_hilbert_machine() {
  constexpr int depth = key_bits;
  struct Prefix {
    int length = 0;
    std::uint8_t digit[key_bits]{};
  };
  auto key_of = [](const Prefix& p) {  // hilbert_key of the prefix's digits, zeros below
    std::array<std::uint32_t, 3> x{0, 0, 0};
    for (int k = 0; k < p.length; ++k) {
      const int level = depth - 1 - k;
      for (int a = 0; a < 3; ++a) x[a] |= static_cast<std::uint32_t>((p.digit[k] >> (2 - a)) & 1) << level;
    }
    return hilbert_key(x);
  };
  auto key_digit = [](std::uint64_t key, int k) { return static_cast<int>((key >> (3 * (depth - 1 - k))) & 7); };
  auto extended = [](Prefix p, int d) {
    p.digit[p.length++] = static_cast<std::uint8_t>(d);
    return p;
  };
  std::array<std::array<std::uint8_t, 8>, HilbertMachine::max_states> signature{};
  std::array<Prefix, HilbertMachine::max_states> representative{};
  auto signature_of = [&](const Prefix& p) {
    std::array<std::uint8_t, 8> out{};
    for (int d = 0; d < 8; ++d) out[d] = static_cast<std::uint8_t>(key_digit(key_of(extended(p, d)), p.length));
    return out;
  };
  HilbertMachine m;
  auto state_of = [&](const Prefix& p) {
    const auto sig = signature_of(p);
    for (int s = 0; s < m.states; ++s)
      if (signature[s] == sig) return s;
    // A cube has 48 orientations, and a curve's states are reached within a
    // few levels: neither bound is ever met.
    assert(m.states < HilbertMachine::max_states && p.length < depth);
    if (m.states == HilbertMachine::max_states) return 0;
    signature[m.states] = sig;
    representative[m.states] = p;
    return m.states++;
  };
  int next[HilbertMachine::max_states][8]{}, bits[HilbertMachine::max_states][8]{};
  state_of(Prefix{});
  for (int s = 0; s < m.states; ++s)  // breadth first: m.states grows as states are found
    for (int d = 0; d < 8; ++d) {
      const Prefix q = extended(representative[s], d);
      bits[s][d] = key_digit(key_of(q), q.length - 1);
      next[s][d] = state_of(q);
    }
  for (int s = 0; s < m.states; ++s) {
    for (int d = 0; d < 8; ++d) m.first[s * 8 + d] = static_cast<std::uint16_t>(next[s][d] << 6 | bits[s][d]);
    for (int d = 0; d < 64; ++d) {
      const int mid = next[s][d >> 3];
      m.pair[s * 64 + d] =
          static_cast<std::uint16_t>(next[mid][d & 7] << 6 | bits[s][d >> 3] << 3 | bits[mid][d & 7]);
    }
  }
  return m;
}

static_assert(key_bits % 2 == 1, "the machine reads one level, then pairs");

// hilbert_key of four lattice points at once (x[k]: point k's axes), their
// machines interleaved so that one's table load waits beside the others'.
void hilbert_keys4(const HilbertMachine& machine, const std::uint32_t x[4][3], std::uint64_t out[4]) {
  std::uint64_t code[4];
  unsigned state[4];
  constexpr int top = 3 * (key_bits - 1);
  for (int k = 0; k < 4; ++k) {
    code[k] = morton_code(x[k]);
    const unsigned e = machine.first[code[k] >> top & 7];
    out[k] = e & 7;
    state[k] = e >> 6;
  }
  for (int shift = top - 6; shift >= 0; shift -= 6)
    for (int k = 0; k < 4; ++k) {
      const unsigned e = machine.pair[state[k] * 64 + (code[k] >> shift & 63)];
      out[k] = out[k] << 6 | (e & 63);
      state[k] = e >> 6;
    }
}

[[maybe_unused]] bool machine_agrees(const HilbertMachine& m) {
  constexpr std::uint32_t all = (1u << key_bits) - 1;
  std::uint64_t state = 0x243f6a8885a308d3ull;
  for (int i = 0; i < 512 + 8; i += 4) {  // the 8 corners, then pseudo-random points
    std::uint32_t x[4][3];
    for (int k = 0; k < 4; ++k)
      for (int a = 0; a < 3; ++a) {
        state += 0x9e3779b97f4a7c15ull;
        x[k][a] = i + k < 8 ? ((i + k) >> a & 1 ? all : 0) : static_cast<std::uint32_t>(mix64(state) & all);
      }
    std::uint64_t keys[4];
    hilbert_keys4(m, x, keys);
    for (int k = 0; k < 4; ++k)
      if (keys[k] != hilbert_key({x[k][0], x[k][1], x[k][2]})) return false;
  }
  return true;
}

const HilbertMachine& hilbert_machine() {
  static const HilbertMachine m = [] {
    HilbertMachine made = make_hilbert_machine();
    assert(made.states == 24 && machine_agrees(made));  // the 3D Hilbert curve has 24 orientations
    return made;
  }();
  return m;
}

struct Keyed {
  std::uint64_t key;
  std::uint32_t index;
  bool operator<(const Keyed& o) const { return key < o.key || (key == o.key && index < o.index); }
};

// Sorts a[0, n) by (key, index), as std::sort with Keyed's operator< would,
// where the keys agree above bit `bits` (63 at the top): a radix sort from
// the most significant digit (11 bits for large ranges, 8 below), each bucket
// sorted on after it, so that after the first pass the work stays in cache
// (1M uniform points: buckets of about 500 items). A digit that every key
// shares is skipped without moving anything (clustered points share their
// keys' top bits); up to 32 items are insertion sorted; keys equal in every
// bit are sorted by index. scratch: room for n items.
void msd_sort(Keyed* a, std::size_t n, Keyed* scratch, int bits) {
  if (n <= 32) {
    for (std::size_t i = 1; i < n; ++i)
      for (std::size_t j = i; j > 0 && a[j] < a[j - 1]; --j) std::swap(a[j], a[j - 1]);
    return;
  }
  if (bits == 0) {  // every key equal
    std::sort(a, a + n);
    return;
  }
  const int width = std::min(bits, n > 65536 ? 11 : 8);
  const int shift = bits - width;
  const std::uint64_t mask = (std::uint64_t{1} << width) - 1;
  // 2 KB of counts on the stack (8 levels deep at most); the wide digit's
  // 16 KB, for large ranges only, on the heap.
  std::uint32_t small[2 * 256 + 1];
  std::vector<std::uint32_t> large(width > 8 ? 2 * (mask + 1) + 1 : 0);
  std::uint32_t* count = width > 8 ? large.data() : small;
  std::uint32_t* start = count + (mask + 1);
  std::fill(count, count + (mask + 1), 0u);
  for (std::size_t i = 0; i < n; ++i) ++count[a[i].key >> shift & mask];
  if (count[a[0].key >> shift & mask] == n) return msd_sort(a, n, scratch, shift);  // one digit: nothing moves
  start[0] = 0;
  for (std::uint64_t d = 0; d <= mask; ++d) start[d + 1] = start[d] + count[d];
  for (std::uint64_t d = 0; d <= mask; ++d) count[d] = start[d];
  for (std::size_t i = 0; i < n; ++i) scratch[count[a[i].key >> shift & mask]++] = a[i];
  std::copy(scratch, scratch + n, a);
  for (std::uint64_t d = 0; d <= mask; ++d)
    if (start[d + 1] - start[d] > 1) msd_sort(a + start[d], start[d + 1] - start[d], scratch, shift);
}

// msd_sort on several threads: the first pass counts and scatters `chunks`
// consecutive parts of the range in parallel (part c's items with digit d
// after those of the parts before c), then the buckets are sorted in
// parallel. The same result: the one order by (key, index).
void msd_sort_parallel(Keyed* a, std::size_t n, Keyed* scratch, unsigned chunks) {
  constexpr int width = 11, shift = 3 * key_bits - width;
  constexpr std::size_t digits = std::size_t{1} << width;
  std::vector<std::uint32_t> count(std::size_t{chunks} * digits);
  auto part = [&](unsigned c) { return n * c / chunks; };
  tbb::task_group_context counting(tbb::task_group_context::isolated);  // for_range.hpp says why
  tbb::parallel_for(0u, chunks, [&](unsigned c) {
    std::uint32_t* mine = count.data() + std::size_t{c} * digits;
    std::fill(mine, mine + digits, 0u);
    for (std::size_t i = part(c); i < part(c + 1); ++i) ++mine[a[i].key >> shift];
  }, counting);
  // Offsets, digit by digit, then part by part within a digit.
  std::vector<std::uint32_t> start(digits + 1);
  std::uint32_t sum = 0;
  for (std::size_t d = 0; d < digits; ++d) {
    start[d] = sum;
    for (unsigned c = 0; c < chunks; ++c) sum += std::exchange(count[c * digits + d], sum);
  }
  start[digits] = sum;
  tbb::task_group_context scattering(tbb::task_group_context::isolated);
  tbb::parallel_for(0u, chunks, [&](unsigned c) {
    std::uint32_t* offset = count.data() + std::size_t{c} * digits;
    for (std::size_t i = part(c); i < part(c + 1); ++i) scratch[offset[a[i].key >> shift]++] = a[i];
  }, scattering);
  tbb::task_group_context sorting(tbb::task_group_context::isolated);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, digits, 16), [&](const tbb::blocked_range<std::size_t>& r) {
    const std::size_t from = start[r.begin()], to = start[r.end()];
    std::copy(scratch + from, scratch + to, a + from);
    for (std::size_t d = r.begin(); d < r.end(); ++d)
      if (start[d + 1] - start[d] > 1) msd_sort(a + start[d], start[d + 1] - start[d], scratch + start[d], shift);
  }, sorting);
}

// Room for the sort, contiguous, mapped for the sort and unmapped after
// it: freed to the heap, its 12 MB at 1M points stayed in the process beside
// the mesh built next. (Not a StableArray: in the mimalloc build that one is
// chunked, not contiguous.)
struct MappedScratch {
  Keyed* items = nullptr;
  std::size_t bytes = 0;
  explicit MappedScratch(std::size_t n) : bytes(n * sizeof(Keyed)) {
    if (n == 0) return;
    void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    items = static_cast<Keyed*>(p);
  }
  ~MappedScratch() {
    if (items) ::munmap(items, bytes);
  }
  MappedScratch(const MappedScratch&) = delete;
  MappedScratch& operator=(const MappedScratch&) = delete;
};

}  // namespace

std::vector<std::uint32_t> spatial_order(std::span<const Point3> points, bool parallel) {
  // CGAL's order (spatial_sort: a BRIO whose rounds are Hilbert sorted), with
  // the Hilbert sort done on fixed-resolution keys: compute, then sort
  // integers, instead of CGAL's median splits, which reach each point
  // through the index at every level (0.3-0.45 s of a 4 s batch of 1M points).
  // The rounds, as CGAL's: a random shuffle, then the last 3/4 of the range
  // sorted and the first 1/4 again split the same way, down to 16 points.
  const std::size_t n = points.size();
  if (n < 64) return cgal_order(points, parallel);
  BoundingBox box;
  {
    std::mutex merging;  // a few hundred pieces at most: their boxes merged under a lock
    for_range(n, parallel, [&](std::size_t begin, std::size_t end) {
      BoundingBox part;
      for (std::size_t i = begin; i < end; ++i) part.add(points[i].x, points[i].y, points[i].z);
      std::lock_guard lock(merging);
      box.add(part.lo[0], part.lo[1], part.lo[2]);
      box.add(part.hi[0], part.hi[1], part.hi[2]);
    });
  }
  // A flat axis maps to 0 there; a box reaching +-DBL_MAX, or a subnormal
  // one, scales without overflow (BoxLattice works on halves and pre-scales).
  const BoxLattice lattice(box.lo, box.hi, 1 << key_bits);
  // Keys in the points' order (reading them in the shuffled order would miss
  // the cache at each one), then the shuffle: Fisher-Yates from a fixed seed,
  // so the order (and the vertex ids it hands out) is the same on every run.
  const RawArray<Keyed> items = make_raw_array<Keyed>(n);  // each written below, in parallel
  auto lattice_point = [&](std::size_t i, std::uint32_t x[3]) {
    const double c[3] = {points[i].x, points[i].y, points[i].z};
    for (int a = 0; a < 3; ++a) x[a] = static_cast<std::uint32_t>(lattice.index(a, c[a]));
  };
  const HilbertMachine& machine = hilbert_machine();
  for_range(n, parallel, [&](std::size_t begin, std::size_t end) {
    std::size_t i = begin;
    for (; i + 4 <= end; i += 4) {  // four at a time, their table walks interleaved
      std::uint32_t at[4][3];
      for (int k = 0; k < 4; ++k) lattice_point(i + k, at[k]);
      std::uint64_t keys[4];
      hilbert_keys4(machine, at, keys);
      for (int k = 0; k < 4; ++k) {
        assert(keys[k] == hilbert_key({at[k][0], at[k][1], at[k][2]}));
        items[i + k] = {keys[k], static_cast<std::uint32_t>(i + k)};
      }
    }
    for (; i < end; ++i) {
      std::uint32_t x[3];
      lattice_point(i, x);
      items[i] = {hilbert_key({x[0], x[1], x[2]}), static_cast<std::uint32_t>(i)};
    }
  });
  // The swaps' partners do not depend on the items: each is drawn 16 swaps
  // ahead and its item fetched meanwhile (the shuffle waits on memory). The
  // same draws, the same order. (1M points, one thread, six alternating
  // runs: spatial_order 50.5 -> 46.5 ms, medians.)
  {
    constexpr std::size_t ahead = 16;  // a power of two
    std::uint64_t state = 0x9e3779b97f4a7c15ull;
    std::size_t partner[ahead];
    std::size_t drawn = n - 1;  // the next i to draw a partner for
    auto draw = [&] {
      state = mix64(state + drawn);
      partner[drawn % ahead] = static_cast<std::size_t>(state % (drawn + 1));
      __builtin_prefetch(&items[partner[drawn % ahead]], 1);
      --drawn;
    };
    while (drawn > 0 && drawn + ahead > n - 1) draw();
    for (std::size_t i = n - 1; i > 0; --i) {
      const std::size_t j = partner[i % ahead];
      if (drawn > 0) draw();
      std::swap(items[i], items[j]);
    }
  }
  // Each round sorted by (key, index) by a radix sort, on several threads
  // where the arena has them and the round is large. The same order either
  // way. (In the engine's batch, on 2 threads, TBB's parallel_sort took as
  // much CPU time as the rest of the order. A least-significant-digit radix
  // sort, 6 passes over the round, took 25 ms for 870k keys on one thread and
  // 24 on two; msd_sort 13 and 8.)
  const unsigned threads = parallel ? static_cast<unsigned>(std::max(1, tbb::this_task_arena::max_concurrency())) : 1;
  const MappedScratch scratch(n - n / 4);
  for (std::size_t end = n; end > 0;) {
    const std::size_t begin = brio_round_begin(end);
    const unsigned chunks = static_cast<unsigned>(std::min<std::size_t>(threads, (end - begin) / 4096));
    if (chunks > 1)
      msd_sort_parallel(items.get() + begin, end - begin, scratch.items, chunks);
    else
      msd_sort(items.get() + begin, end - begin, scratch.items, 3 * key_bits);
    assert(std::is_sorted(items.get() + begin, items.get() + end));
    end = begin;
  }
  // Keys too coarse for the points (a cluster far smaller than the box, or a
  // subnormal box): many
  // distinct points on one key leave them in shuffled order, so walks would
  // get long. Then CGAL's median splits, which adapt to any density.
  // (Copies of one point share their key harmlessly: not counted.)
  std::atomic<std::size_t> shared_keys{0};
  for_range(n, parallel, [&](std::size_t begin, std::size_t end) {
    std::size_t here = 0;
    for (std::size_t i = std::max<std::size_t>(begin, 1); i < end; ++i)
      here += items[i].key == items[i - 1].key && !(points[items[i].index] == points[items[i - 1].index]);
    shared_keys.fetch_add(here, std::memory_order_relaxed);
  });
  if (shared_keys.load() > n / 64) return cgal_order(points, parallel);
  std::vector<std::uint32_t> order(n);
  for_range(n, parallel, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) order[i] = items[i].index;
  });
  return order;
}

}  // namespace pdt::detail
