#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# ThreadSanitizer in one command: install the dependencies, build the
# instrumented oneTBB (once; scripts/build-tsan-tbb.sh skips it when it is up
# to date), then configure, build and test the tsan preset in build-tsan/.
# Arguments go to ctest, e.g. `scripts/tsan.sh -R engine`. Each step says how
# long it took.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# shellcheck source=lib/steps.sh
. scripts/lib/steps.sh
steps_init tsan

step "install dependencies" ./scripts/install-deps.sh
step "instrumented oneTBB (build-tsan-deps/tbb-tsan)" ./scripts/build-tsan-tbb.sh
step "configure (tsan preset)" cmake --preset tsan
step "build (tsan preset)" cmake --build --preset tsan
step "test (tsan preset)" ctest --preset tsan "$@"
steps_done
