// SPDX-License-Identifier: MIT
// Which queue should carry operations from the master to a worker?
// Compares oneTBB's concurrent_queue (what lib/engine.cpp used then; it has its
// own intrusive queue now, lib/block_queue.hpp) with
// Boost.Lockfree's queue on the engine's traffic pattern: one or more
// producers push operation records, one consumer pops them, and the consumer
// also re-pushes a share of them (rollbacks go to the back of its own queue).
//
// Boost.Lockfree's queue needs trivially copyable elements of fixed size, so
// it carries pointers to records from a preallocated array; the TBB queue
// carries the records themselves (as the engine does: 96-byte records with a
// std::function inside).
//
// usage: bench_queues [--ops N] [--producers P] [--requeue PERCENT]
#include <oneapi/tbb/concurrent_queue.h>

#include <boost/lockfree/queue.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace {

struct Record {  // the shape of the engine's queued operation
  int kind = 0;
  double point[3] = {0, 0, 0};
  std::uint32_t vertex = 0;
  std::uint64_t stamp = 0, ticket = 0;
  std::function<void()> done;
  void* awaiter = nullptr;
};

struct Config {
  std::size_t ops = 2'000'000;
  unsigned producers = 1;
  unsigned requeue_percent = 2;
};

template <class Push, class Pop>
double run(const Config& cfg, Push push, Pop pop) {
  std::atomic<std::size_t> consumed{0};
  auto t0 = std::chrono::steady_clock::now();
  std::vector<std::thread> producers;
  const std::size_t per = cfg.ops / cfg.producers;
  for (unsigned p = 0; p < cfg.producers; ++p)
    producers.emplace_back([&, p] {
      for (std::size_t i = 0; i < per; ++i) push(p * per + i);
    });
  std::thread consumer([&] {
    std::size_t n = 0, requeued = 0;
    std::uint64_t rng = 88172645463325252ull;
    while (n < per * cfg.producers) {
      std::size_t id;
      if (!pop(id)) continue;
      rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
      if (rng % 100 < cfg.requeue_percent && requeued < cfg.ops) {
        ++requeued;
        push(id);  // a rollback: back of the queue
        continue;
      }
      ++n;
    }
    consumed = n;
  });
  for (auto& t : producers) t.join();
  consumer.join();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  Config cfg;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&] {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_queues: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return std::strtoull(argv[++i], nullptr, 10);
    };
    if (a == "--ops") cfg.ops = next();
    else if (a == "--producers") cfg.producers = static_cast<unsigned>(std::max(1ull, next()));
    else if (a == "--requeue") cfg.requeue_percent = static_cast<unsigned>(next());
    else {
      std::fprintf(stderr, "usage: bench_queues [--ops N] [--producers P] [--requeue PERCENT]\n");
      return 2;
    }
  }
  std::vector<Record> records(cfg.ops);
  for (std::size_t i = 0; i < cfg.ops; ++i) records[i].ticket = i;

  tbb::concurrent_queue<Record> tq;
  double t_tbb = run(
      cfg, [&](std::size_t i) { tq.push(records[i]); },
      [&](std::size_t& id) {
        Record r;
        if (!tq.try_pop(r)) return false;
        id = r.ticket;
        return true;
      });

  boost::lockfree::queue<Record*> bq(1024);
  double t_boost = run(
      cfg, [&](std::size_t i) { while (!bq.push(&records[i])) {} },
      [&](std::size_t& id) {
        Record* r;
        if (!bq.pop(r)) return false;
        id = r->ticket;
        return true;
      });

  std::printf("queue benchmark: %zu operations, %u producer(s), 1 consumer, %u%% re-queued (rollbacks)\n", cfg.ops,
              cfg.producers, cfg.requeue_percent);
  std::printf("  %-34s %8.3f s  %6.1f Mops/s\n", "oneTBB concurrent_queue<Record>", t_tbb, cfg.ops / t_tbb / 1e6);
  std::printf("  %-34s %8.3f s  %6.1f Mops/s\n", "boost::lockfree::queue<Record*>", t_boost, cfg.ops / t_boost / 1e6);
  std::printf("  ratio boost/tbb %.2f (below 1: Boost.Lockfree is faster)\n", t_boost / t_tbb);
  return 0;
}
