// SPDX-License-Identifier: MIT
// The engine's ticket table (lib/tickets.hpp) on its own: a large batch's
// tickets live in a range whose slots follow the run order; single tickets
// and small batches come out of the open range, in ticket order, which a
// large batch closes; every lookup by ticket finds them there; once most are
// released and none is pending a range is compacted into the hashed shards,
// and the live tickets keep their state; tickets whose vertex is gone are
// swept from ranges too.
#include <catch2/catch.hpp>

#include <algorithm>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "pdt/error.hpp"
#include "stable_array.hpp"
#include "storage.hpp"
#include "tickets.hpp"

using pdt::detail::StableArray;
using pdt::detail::TicketPosition;
using pdt::detail::TicketRange;
using pdt::detail::TicketState;
using pdt::detail::TicketTable;
using pdt::detail::VertexRec;

namespace {

// n vertices 1..n, vertex v with stamp 1000 + v, as the table reads them.
struct Vertices {
  StableArray<VertexRec> verts;
  explicit Vertices(std::size_t n) : verts(n + 1) {
    verts.grow(n + 1);
    for (std::size_t v = 1; v <= n; ++v) {
      verts[v].multiplicity = 1;
      verts[v].stamp.store(1000 + v);
    }
  }
};

// A permutation of 0..n-1 (the run order of a batch), fixed by seed.
std::vector<std::uint32_t> run_order(std::size_t n, unsigned seed) {
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  return order;
}

pdt::ErrorCode error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const pdt::Error& e) {
    return e.code();
  }
  FAIL("no pdt::Error thrown");
  return pdt::ErrorCode::invalid_argument;
}

}  // namespace

TEST_CASE("tickets: a small batch and single tickets come from the open range, a large batch gets a range in run order",
          "[tickets]") {
  TicketTable table;
  const std::size_t small = TicketTable::range_min - 1, large = 4 * TicketTable::range_min + 5;
  Vertices v(large);
  const TicketTable::Issued a = table.issue_ordered(run_order(small, 1));
  REQUIRE(a.range != nullptr);
  REQUIRE(a.range->position == nullptr);  // ticket order
  REQUIRE(a.first == 0);
  REQUIRE(table.ranged() == small);
  const TicketTable::Issued single = table.issue(1);
  REQUIRE(single.first == small);
  REQUIRE(single.range == a.range);
  REQUIRE(single.range->slot_of(single.first) == small);
  // The open range's next slot is no insertion yet.
  REQUIRE(error_of([&] { (void)table.result(small + 1, v.verts); }) == pdt::ErrorCode::invalid_argument);
  REQUIRE(error_of([&] { (void)table.claim_undo(small + 1, v.verts); }) == pdt::ErrorCode::unknown_vertex);
  const std::vector<std::uint32_t> order = run_order(large, 2);
  const TicketTable::Issued b = table.issue_ordered(order);
  REQUIRE(b.range != nullptr);
  REQUIRE(b.range != a.range);
  REQUIRE(b.first == small + 1);  // consecutive: the open range was closed after its last ticket
  REQUIRE(a.range->n == small + 1);
  REQUIRE(table.ranged() == small + 1 + large);
  REQUIRE(table.issued() == small + 1 + large);
  REQUIRE(table.live() == small + 1 + large);

  // Finish the range's tickets in run order, each at its position; a few by
  // lookup alone (no position), as a finish without a hint would.
  for (std::uint32_t k = 0; k < large; ++k) {
    const std::uint64_t t = b.first + order[k];
    REQUIRE(table.view(t).state == TicketState::pending);
    const TicketPosition at = k % 97 == 0 ? TicketPosition{} : TicketPosition{b.range, k};
    REQUIRE(table.finish_inserted(t, k + 1, true, 1000 + k + 1, at) == nullptr);
  }
  for (std::uint32_t k = 0; k < large; ++k) {
    const std::uint64_t t = b.first + order[k];
    const pdt::InsertResult r = table.result(t, v.verts);
    REQUIRE(r.vertex == k + 1);
    REQUIRE(r.incarnation == 1000 + k + 1);
  }
  // Out of range, before and after.
  REQUIRE(error_of([&] { (void)table.result(table.issued(), v.verts); }) == pdt::ErrorCode::invalid_argument);
  REQUIRE(table.view(single.first).state == TicketState::pending);
  // The next single ticket opens a new range after the batch.
  const TicketTable::Issued next = table.issue(1);
  REQUIRE(next.first == small + 1 + large);
  REQUIRE(next.range != a.range);
  REQUIRE(next.range != b.range);
  REQUIRE(next.range->slot_of(next.first) == 0);
  REQUIRE(table.ranged() == small + 2 + large);
}

TEST_CASE("tickets: one at a time they fill open ranges in ticket order, each twice the last up to a maximum; a full "
          "range compacts, the open one waits",
          "[tickets]") {
  TicketTable table;
  std::vector<std::uint32_t> sizes;  // the ranges' sizes, as they fill: 64, 128, ..., max, max
  for (std::uint32_t size = TicketTable::open_range_min; size < TicketTable::open_range_max; size *= 2)
    sizes.push_back(size);
  sizes.push_back(TicketTable::open_range_max);
  sizes.push_back(TicketTable::open_range_max);
  std::size_t full = 0;
  for (std::uint32_t size : sizes) full += size;
  const std::size_t n = full + 100;  // then the next open range's first 100
  Vertices v(n);
  std::vector<TicketTable::Issued> issued;
  std::vector<std::uint32_t> seen;  // sizes of the ranges filled, in order
  for (std::size_t t = 0; t < n; ++t) {
    issued.push_back(table.issue(1));
    const TicketTable::Issued& i = issued.back();
    REQUIRE(i.first == t);
    if (t > 0 && i.range == issued[t - 1].range) {
      REQUIRE(i.range->slot_of(t) == i.range->slot_of(t - 1) + 1);
    } else {
      REQUIRE(i.range->slot_of(t) == 0);
      if (t > 0) {
        const TicketRange* last = issued[t - 1].range;
        REQUIRE(last->slot_of(t - 1) + 1 == last->n);  // filled to its last slot
        seen.push_back(last->n);
      }
    }
  }
  REQUIRE(seen == sizes);
  REQUIRE(table.ranged() == n);
  REQUIRE(table.live() == n);
  REQUIRE(error_of([&] { (void)table.claim_undo(n, v.verts); }) == pdt::ErrorCode::unknown_vertex);
  // Finished in a scattered order at their positions, some by lookup alone.
  const std::vector<std::uint32_t> order = run_order(n, 6);
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t t = order[k];
    const TicketPosition at = k % 89 == 0 ? TicketPosition{} : TicketPosition{issued[t].range, issued[t].range->slot_of(t)};
    REQUIRE(table.finish_inserted(t, t + 1, true, 1000 + t + 1, at) == nullptr);
  }
  for (std::uint32_t t = 0; t < n; ++t) REQUIRE(table.result(t, v.verts).vertex == t + 1);
  // Undo all but every 16th: the full ranges go to the shards; the open one,
  // whose tickets not given out count as pending, stays.
  for (std::uint32_t t = 0; t < n; ++t) {
    if (t % 16 == 0) continue;
    REQUIRE(table.claim_undo(t, v.verts).vertex == t + 1);
    table.release(t);
  }
  REQUIRE(table.ranged() == 100);
  REQUIRE(table.live() == (n + 15) / 16);
  // A large batch closes it: 7 of its 100 live, none pending: compacted.
  const TicketTable::Issued b = table.issue_ordered(run_order(TicketTable::range_min, 7));
  REQUIRE(b.first == n);
  REQUIRE(table.ranged() == TicketTable::range_min);
  for (std::uint32_t t = 0; t < n; ++t) {
    if (t % 16 == 0)
      REQUIRE(table.result(t, v.verts).vertex == t + 1);
    else
      REQUIRE(error_of([&] { (void)table.result(t, v.verts); }) == pdt::ErrorCode::invalid_argument);
  }
  // The next open range starts again at the smallest size.
  const TicketTable::Issued next = table.issue(1);
  REQUIRE(next.range->slot_of(next.first) == 0);
  REQUIRE(next.range->n == TicketTable::open_range_min);
}

TEST_CASE("tickets: an open range filled to its last slot is an ordinary one: compacted, and the next ticket opens another",
          "[tickets]") {
  TicketTable table;
  const std::uint32_t size = TicketTable::open_range_min;  // the first open range's
  Vertices v(size);
  TicketRange* first_range = nullptr;
  for (std::uint32_t t = 0; t < size; ++t) {
    const TicketTable::Issued i = table.issue(1);
    if (t == 0) first_range = i.range;
    REQUIRE(i.range == first_range);
    REQUIRE(table.finish_inserted(t, t + 1, true, 1000 + t + 1, {i.range, t}) == nullptr);
  }
  for (std::uint32_t t = 0; t < size; ++t) {
    if (t % 16 == 0) continue;
    (void)table.claim_undo(t, v.verts);
    table.release(t);
  }
  REQUIRE(table.ranged() == 0);  // none pending, an eighth live or less: compacted
  const TicketTable::Issued next = table.issue(1);
  REQUIRE(next.first == size);
  REQUIRE(next.range->slot_of(size) == 0);
  REQUIRE(table.ranged() == 1);
  for (std::uint32_t t = 0; t < size; t += 16) REQUIRE(table.result(t, v.verts).vertex == t + 1);
}

TEST_CASE("tickets: single tickets and large batches alternating leave at most the smallest open range unused each time",
          "[tickets]") {
  TicketTable table;
  const std::size_t rounds = 40;
  std::size_t batch_tickets = 0;
  for (std::size_t round = 0; round < rounds; ++round) {
    const TicketTable::Issued single = table.issue(1);
    REQUIRE(single.range->n == TicketTable::open_range_min);
    const TicketTable::Issued b = table.issue_ordered(run_order(TicketTable::range_min, static_cast<unsigned>(round)));
    REQUIRE(b.first == single.first + 1);
    REQUIRE(single.range->n == 1);  // closed at its one ticket
    batch_tickets += TicketTable::range_min;
  }
  REQUIRE(table.issued() == rounds + batch_tickets);
  REQUIRE(table.slots_allocated() == batch_tickets + rounds * TicketTable::open_range_min);
}

TEST_CASE("tickets: a range closed after a few tickets is judged by the slots it holds: its live ticket moves to the "
          "shards once finished",
          "[tickets]") {
  TicketTable table;
  Vertices v(2);
  // Open ranges of 64, 128, ... up to half the largest size, each filled,
  // finished and undone (so compacted away): the next one has the largest.
  std::uint64_t t = 0;
  for (std::uint32_t size = TicketTable::open_range_min; size < TicketTable::open_range_max; size *= 2)
    for (std::uint32_t k = 0; k < size; ++k, ++t) {
      const TicketTable::Issued i = table.issue(1);
      REQUIRE(i.first == t);
      table.finish_inserted(t, 1, true, 1001, {i.range, i.range->slot_of(t)});
      (void)table.claim_undo(t, v.verts);
      table.release(t);
    }
  REQUIRE(table.ranged() == 0);
  const TicketTable::Issued kept = table.issue(1);
  REQUIRE(kept.range->capacity == TicketTable::open_range_max);
  const std::vector<std::uint32_t> order = run_order(TicketTable::range_min, 9);
  const TicketTable::Issued b = table.issue_ordered(order);  // closes the open range at its one ticket, pending
  REQUIRE(kept.range->n == 1);
  for (std::uint32_t k = 0; k < order.size(); ++k) {
    table.finish_inserted(b.first + order[k], 1, true, 1001, {b.range, k});
    (void)table.claim_undo(b.first + order[k], v.verts);
    table.release(b.first + order[k]);
  }
  REQUIRE(table.ranged() == 1);  // the kept ticket's range: pending
  REQUIRE(table.finish_inserted(kept.first, 2, true, 1002, {kept.range, 0}) == nullptr);
  REQUIRE(table.ranged() == 0);  // one live of 4,096 slots: to the shards at its finish
  REQUIRE(table.slots_allocated() <= 16 * 16);  // each shard's smallest table, not the range's 4,096
  REQUIRE(table.result(kept.first, v.verts).vertex == 2);
  REQUIRE(table.claim_undo(kept.first, v.verts).vertex == 2);
}

TEST_CASE("tickets: an undo parked on a pending ranged ticket comes back at its finish", "[tickets]") {
  TicketTable table;
  const std::size_t n = TicketTable::range_min;
  const std::vector<std::uint32_t> order = run_order(n, 3);
  const TicketTable::Issued b = table.issue_ordered(order);
  REQUIRE(b.range != nullptr);
  pdt::detail::OpRecord undo;
  const std::uint64_t t = b.first + order[7];
  REQUIRE(table.park(t, &undo) == nullptr);  // pending: parked
  REQUIRE(table.finish_inserted(t, 5, true, 1005, {b.range, 7}) == &undo);
  REQUIRE(table.park(t, &undo) == &undo);  // done: runs now
}

TEST_CASE("tickets: a mostly released range is compacted; its live tickets keep their state", "[tickets]") {
  TicketTable table;
  const std::size_t n = 8 * TicketTable::range_min;
  const std::vector<std::uint32_t> order = run_order(n, 4);
  Vertices v(n);
  const TicketTable::Issued b = table.issue_ordered(order);
  // All but the last one finished; release 15 of 16 of the finished ones:
  // a pending ticket keeps the range.
  for (std::uint32_t k = 0; k + 1 < n; ++k)
    table.finish_inserted(b.first + order[k], k + 1, true, 1000 + k + 1, {b.range, k});
  std::vector<std::uint64_t> kept;
  for (std::uint32_t k = 0; k + 1 < n; ++k) {
    const std::uint64_t t = b.first + order[k];
    if (k % 16 == 3) {
      kept.push_back(t);
      continue;
    }
    (void)table.claim_undo(t, v.verts);
    table.release(t);
  }
  REQUIRE(table.ranged() == n);  // one pending: not compacted
  REQUIRE(table.live() == kept.size() + 1);
  // The last one finishes, failed; the next release compacts.
  table.finish_failed(b.first + order[n - 1], std::make_exception_ptr(std::bad_alloc()), {b.range, std::uint32_t(n - 1)});
  const std::uint64_t released = kept.back();
  kept.pop_back();
  (void)table.claim_undo(released, v.verts);
  table.release(released);
  REQUIRE(table.ranged() == 0);
  REQUIRE(table.live() == kept.size() + 1);
  // Every kept ticket has its vertex; the released ones are gone; the failed
  // one still says so (its error was kept in its shard).
  for (std::uint64_t t : kept) {
    const pdt::InsertResult r = table.result(t, v.verts);
    REQUIRE(r.incarnation == 1000 + r.vertex);
    REQUIRE(table.view(t).state == TicketState::inserted);
  }
  REQUIRE(error_of([&] { (void)table.result(released, v.verts); }) == pdt::ErrorCode::invalid_argument);
  REQUIRE(error_of([&] { (void)table.claim_undo(released, v.verts); }) == pdt::ErrorCode::unknown_vertex);
  REQUIRE_THROWS_AS(table.result(b.first + order[n - 1], v.verts), std::bad_alloc);
  // And they can still be undone, from the shards now.
  for (std::uint64_t t : kept) {
    REQUIRE(table.claim_undo(t, v.verts).state == TicketState::inserted);
    table.release(t);
  }
  REQUIRE(table.live() == 1);
}

TEST_CASE("tickets: a sweep erases the ranged tickets whose vertex is gone, and compacts", "[tickets]") {
  TicketTable table;
  const std::size_t n = 70000;  // past the sweep's first threshold (2^16 live tickets)
  const std::vector<std::uint32_t> order = run_order(n, 5);
  Vertices v(n);
  const TicketTable::Issued b = table.issue_ordered(order);
  for (std::uint32_t k = 0; k < n; ++k) table.finish_inserted(b.first + order[k], k + 1, true, 1000 + k + 1, {b.range, k});
  // Every vertex but each tenth is removed (a new incarnation, or none).
  for (std::uint32_t k = 0; k < n; ++k)
    if (k % 10 != 0) v.verts[k + 1].stamp.store(0);
  table.sweep_if_large(v.verts, n / 10);
  REQUIRE(table.live() == n / 10);
  REQUIRE(table.ranged() == 0);  // a tenth live: compacted
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint64_t t = b.first + order[k];
    if (k % 10 == 0)
      REQUIRE(table.result(t, v.verts).vertex == k + 1);
    else
      REQUIRE(error_of([&] { (void)table.result(t, v.verts); }) == pdt::ErrorCode::invalid_argument);
  }
}

TEST_CASE("tickets: large batches issued from several threads at once, beside single tickets, get disjoint "
          "consecutive tickets and slots in their own run order",
          "[tickets]") {
  // A large batch's range is made outside the table's mutex (in parallel)
  // for the tickets next at that moment, and made again when another issue
  // came first: whatever the interleaving, every ticket is issued once.
  TicketTable table;
  struct Batch {
    std::vector<std::uint32_t> order;
    TicketTable::Issued issued;
  };
  constexpr unsigned threads = 4, batches = 3, singles = 40;
  std::vector<std::vector<Batch>> made(threads);
  std::vector<std::vector<std::uint64_t>> single_tickets(threads);
  std::vector<std::thread> pool;
  for (unsigned i = 0; i < threads; ++i)
    pool.emplace_back([&, i] {
      for (unsigned b = 0; b < batches; ++b) {
        Batch batch{run_order(TicketTable::range_min + 997 * i + 131 * b, 10 * i + b), {}};
        batch.issued = table.issue_ordered(batch.order);
        made[i].push_back(std::move(batch));
        for (unsigned s = 0; s < singles; ++s) single_tickets[i].push_back(table.issue(1).first);
      }
    });
  for (std::thread& t : pool) t.join();
  std::vector<std::pair<std::uint64_t, std::uint64_t>> spans;  // [first, end) of every issue
  for (unsigned i = 0; i < threads; ++i) {
    for (const Batch& b : made[i]) {
      const std::size_t n = b.order.size();
      spans.emplace_back(b.issued.first, b.issued.first + n);
      REQUIRE(b.issued.range->first == b.issued.first);
      REQUIRE(b.issued.range->n == n);
      for (std::uint32_t k = 0; k < n; ++k) {
        const std::uint64_t t = b.issued.first + b.order[k];
        REQUIRE(b.issued.range->slot_of(t) == k);
        REQUIRE(b.issued.range->slots[k].key == t + 1);
        REQUIRE(b.issued.range->slots[k].state == TicketState::pending);
      }
    }
    for (std::uint64_t t : single_tickets[i]) spans.emplace_back(t, t + 1);
  }
  std::sort(spans.begin(), spans.end());
  std::uint64_t next = 0;
  for (const auto& [first, end] : spans) {
    REQUIRE(first == next);  // no ticket twice, none skipped
    next = end;
  }
  REQUIRE(next == table.issued());
  REQUIRE(table.live() == table.issued());
}
