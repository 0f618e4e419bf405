// SPDX-License-Identifier: MIT
// The README's example: a refiner's view of pdt. Built and run by the tests.
#include <pdt/pdt.hpp>

#include <coroutine>
#include <cstdio>
#include <exception>
#include <random>

// A minimal fire-and-forget coroutine type, enough to co_await the engine.
struct Task {
  struct promise_type {
    Task get_return_object() { return {}; }
    std::suspend_never initial_suspend() noexcept { return {}; }
    std::suspend_never final_suspend() noexcept { return {}; }
    void return_void() {}
    void unhandled_exception() { std::terminate(); }
  };
};

// Insert a point, and take it out again if the refiner decides so.
Task refine_one(pdt::Engine& engine, pdt::Point3 p, bool keep) {
  pdt::InsertResult r = co_await engine.insert(p);   // runs on the engine's workers
  if (!keep) co_await engine.remove(r.vertex);
}

int main() {
  // Sequential: exact insertion and removal; the result equals CGAL's.
  pdt::Triangulation t;
  pdt::VertexId a = t.insert({0, 0, 0}).vertex;
  for (pdt::Point3 p : {pdt::Point3{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}}) t.insert(p);
  t.remove(a);
  std::printf("sequential: %zu vertices, %zu tetrahedra\n", t.number_of_vertices(), t.number_of_finite_cells());

  // Parallel: a live stream of insertions and removals on all cores.
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  {
    pdt::Engine engine(t, pdt::Box{{0, 0, 0}, {1, 1, 1}});
    for (int i = 0; i < 100000; ++i) refine_one(engine, {u(rng), u(rng), u(rng)}, i % 10 != 0);
    engine.drain();
    std::printf("engine: %u workers, %llu operations\n", engine.workers(),
                static_cast<unsigned long long>(engine.stats().total().completed));
  }
  std::string why;
  bool ok = t.validate(&why);
  std::printf("parallel: %zu vertices, %zu tetrahedra, %s\n", t.number_of_vertices(), t.number_of_finite_cells(),
              ok ? "valid" : why.c_str());
  return ok && t.number_of_vertices() == 4 + 90000 ? 0 : 1;
}
