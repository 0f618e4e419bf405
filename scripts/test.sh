#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The README's test command (and CI's, through .ci/run): install the
# dependencies, then build and pass the whole suite in both allocator builds,
# pdt's chunked pool (release preset) and mimalloc. The mimalloc build skips
# the benchmarks, which the suite does not need, and the shared-library package
# test, which the release run already made.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
./scripts/install-deps.sh
cmake --preset release
cmake --build --preset release
ctest --preset release
cmake --preset mimalloc
cmake --build --preset mimalloc --target pdt_tests pdt_fault_tests pdt_fuzz pdt_tool quickstart
ctest --preset mimalloc -LE package-shared  # the shared-library package test runs once, in the release build
