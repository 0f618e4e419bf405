#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds oneTBB with -fsanitize=thread for the tsan preset, from Debian's own
# source package (the same version as the installed libtbb-dev), and installs it
# into build-tsan-deps/tbb-tsan. ThreadSanitizer cannot see the synchronisation
# inside Debian's uninstrumented libtbb and reports races on every hand-over
# between TBB tasks; with an instrumented libtbb those reports go away and what
# remains is worth reading.
#
# Idempotent: when build-tsan-deps/tbb-tsan already holds a build of the same
# source version with the same compiler and options, it does nothing (and does
# not touch apt or the network). Run from anywhere; paths are relative to the
# repository root. Needs libtbb-dev (scripts/install-deps.sh) and, the first
# time, Debian's package archive: it adds a deb-src entry when none is
# configured, installs cmake, ninja, g++ and dpkg-dev when missing, and fetches
# the source with `apt-get source`. Uses sudo for apt only when not root.
#
# Environment: PDT_TSAN_TBB_JOBS (default: all cores) for the build.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

deps_dir=$PWD/build-tsan-deps
prefix=$deps_dir/tbb-tsan          # the tsan preset's PDT_TBB_DIR points into this
stamp=$prefix/pdt-tsan-stamp
jobs=${PDT_TSAN_TBB_JOBS:-$(nproc)}

current_step=""
# Name the step that failed: with set -e the script would otherwise just stop.
trap 'rc=$?; if [ $rc -ne 0 ]; then echo "build-tsan-tbb: FAILED at step: ${current_step:-setup} (exit $rc)" >&2; fi' EXIT
step() {
  current_step="$1"
  echo
  echo "==> build-tsan-tbb: $current_step"
}
fail() {
  echo "build-tsan-tbb: $*" >&2
  exit 1
}

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

step "find the oneTBB version to build"
# The same source as the installed libtbb-dev, so the instrumented build and
# the normal presets run the same oneTBB.
version=$(dpkg-query -W -f='${Version}' libtbb-dev 2>/dev/null || true)
[ -n "$version" ] || fail "libtbb-dev is not installed: run scripts/install-deps.sh first"
echo "    libtbb-dev $version -> source package onetbb=$version"

cmake_args=(
  -G Ninja
  -DCMAKE_BUILD_TYPE=RelWithDebInfo
  # TSan's reports need frames; -O2 -g (RelWithDebInfo) keeps the runtime usable.
  "-DCMAKE_CXX_FLAGS=-fno-omit-frame-pointer"
  "-DCMAKE_C_FLAGS=-fno-omit-frame-pointer"
  -DCMAKE_INSTALL_PREFIX="$prefix"
  -DCMAKE_INSTALL_LIBDIR=lib
  -DTBB_SANITIZE=thread
  -DTBB_TEST=OFF
  -DTBB_EXAMPLES=OFF
  # oneTBB's TBB_STRICT adds -Werror; GCC 12 warns where oneTBB 2021.8 did not expect it.
  -DTBB_STRICT=OFF
  # tbbbind (NUMA/hybrid-CPU support through hwloc) is not needed to find races.
  -DTBB_DISABLE_HWLOC_AUTOMATIC_SEARCH=ON
)
# What the stamp records: a change in any of these rebuilds. The compiler is
# CMake's default, as for pdt's own presets ($CXX, else c++).
cxx=${CXX:-c++}
make_stamp() {
  echo "onetbb $version"
  echo "compiler $( command -v "$cxx" > /dev/null && "$cxx" --version | head -n 1 || echo none)"
  echo "options ${cmake_args[*]}"
}

if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$(make_stamp)" ] && [ -f "$prefix/lib/cmake/TBB/TBBConfig.cmake" ]; then
  echo
  echo "build-tsan-tbb: $prefix is up to date (onetbb $version, -fsanitize=thread); nothing to do"
  exit 0
fi
if [ -d "$prefix" ]; then
  echo "    $prefix exists but does not match (stale or unfinished build): rebuilding it"
fi

step "install build tools (cmake, ninja, g++, dpkg-dev)"
tools=(build-essential cmake ninja-build dpkg-dev)
missing=()
for p in "${tools[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "    all present"
else
  echo "    installing ${missing[*]}"
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# --- deb-src -----------------------------------------------------------------
have_source() {
  apt-cache showsrc --only-source onetbb 2>/dev/null | grep -qxF "Version: $version"
}
# deb_src_configured, add_deb_src
. scripts/lib/deb_src.sh

step "make Debian's source packages available (deb-src)"
if have_source; then
  echo "    onetbb $version source is already known to apt"
else
  add_deb_src "build-tsan-tbb.sh (onetbb)"
  $SUDO apt-get update -q
  have_source || fail "apt knows no source for onetbb $version (apt-cache showsrc onetbb): if it lists a newer" \
    "version, upgrade libtbb-dev to it (scripts/install-deps.sh, apt-get install --only-upgrade libtbb-dev)"
fi

step "fetch and unpack the onetbb $version source (apt-get source)"
src_parent=$deps_dir/src/onetbb-$version
if [ -f "$src_parent/.unpacked" ]; then
  echo "    already unpacked in $src_parent"
else
  rm -rf "$src_parent"
  mkdir -p "$src_parent"
  # apt-get source unpacks with dpkg-source, which applies Debian's patches.
  (cd "$src_parent" && apt-get source -q "onetbb=$version")
  touch "$src_parent/.unpacked"
fi
src_dir=$(find "$src_parent" -mindepth 2 -maxdepth 2 -name CMakeLists.txt -printf '%h\n' | head -n 1)
[ -n "$src_dir" ] || fail "no oneTBB source tree (CMakeLists.txt) under $src_parent"
echo "    source: $src_dir"

step "configure oneTBB (TBB_SANITIZE=thread, RelWithDebInfo)"
build_dir=$deps_dir/tbb-build
rm -rf "$build_dir"
cmake -S "$src_dir" -B "$build_dir" "${cmake_args[@]}"

step "build oneTBB ($jobs jobs)"
cmake --build "$build_dir" --parallel "$jobs"

step "install into $prefix"
rm -rf "$prefix"
cmake --install "$build_dir"
make_stamp > "$stamp"

current_step=""
echo
echo "build-tsan-tbb: done; instrumented oneTBB $version is in $prefix"
