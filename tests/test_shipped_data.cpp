// SPDX-License-Identifier: MIT
// The real point set shipped in data/ (data/README.md): it runs everywhere,
// with or without ../shared/data.
#include <catch2/catch.hpp>
#include <filesystem>
#include <string>
#include <vector>

#include "common/cgal_reference.hpp"
#include "common/engine_run.hpp"
#include "common/streams.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"

using namespace pdt_test;

#ifndef PDT_REPO_DATA
#error "PDT_REPO_DATA must name the repository's data/ directory"
#endif

TEST_CASE("shipped data: kitten.xyz gives CGAL's triangulation, sequentially and on the engine", "[data][shipped]") {
  const std::string path = std::string(PDT_REPO_DATA) + "/kitten.xyz";
  REQUIRE(std::filesystem::exists(path));  // shipped: never skipped
  const std::vector<pdt::Point3> pts = pdt::read_points(path);
  REQUIRE(pts.size() == 5210);
  {
    pdt::Triangulation t;
    (void)t.insert_batch(pts);
    require_valid(t);
    require_same_as_cgal(t, pts);
  }
  // A stream: all of it, 30% of the insertions undone, interleaved.
  const pdt::OpStream s = stream_of(pts, 0.3, 7);
  pdt::Triangulation seq;
  replay_sequential(seq, s);
  for (unsigned threads : {1u, 2u, 8u}) {
    INFO(threads << " workers");
    pdt::Triangulation t;
    const EngineRun run = replay_engine(t, s, *s.box, options_with(threads));
    require_stats(run, s.ops.size(), threads);
    require_result(t, s, &seq);
  }
}
