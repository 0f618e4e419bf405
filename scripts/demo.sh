#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The README's first command: install dependencies, build the release preset, then
# generate 1M points with 10% interleaved removals, replay them on all cores with
# validation, and run the sequential benchmark.
#
# Environment overrides: PDT_DEMO_POINTS (default 1000000), PDT_DEMO_THREADS
# (default 0 = all cores), PDT_DEMO_DIR (default build/demo, for the .opsb stream).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

points=${PDT_DEMO_POINTS:-1000000}
threads=${PDT_DEMO_THREADS:-0}
out_dir=${PDT_DEMO_DIR:-build/demo}
stream="$out_dir/uniform-${points}-interleaved.opsb"

# shellcheck source=lib/steps.sh
. scripts/lib/steps.sh
steps_init demo

step "install dependencies" ./scripts/install-deps.sh
step "configure (release preset)" cmake --preset release
# Only what the demo runs: the test suite is the CI's job (.ci/run).
step "build pdt and bench_sequential" cmake --build --preset release --target pdt_tool bench_sequential
mkdir -p "$out_dir"
step "generate $points uniform points, 10% interleaved removals" \
  build/pdt gen --dist uniform --points "$points" --remove-fraction 0.1 --interleaved --out "$stream"
step "replay the stream (threads: $threads, 0 = all cores) and validate" \
  build/pdt run "$stream" --threads "$threads" --validate
step "the same workload against CGAL (sequential benchmark)" build/bench_sequential --points "$points" --dists uniform
steps_done
echo
echo "demo: all steps passed"
