#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Packs what bench/scaling.sh needs on a lent machine without our dependencies (the
# 16-core one is a bare Ubuntu 24.04): the Release binaries, and every shared library
# they link except the C library's own, which that machine has (libc, libm, libpthread,
# libdl, librt, the loader). The libraries go in one xz archive (gmsh's, for HXT in
# bench_peers, are about 100 MB as they are, 30 MB packed). DIR/COMMIT names the commit.
# Usage: bench/device-pack.sh [DIR]    (default .dev, which git ignores)
# Then carry DIR and run there: bench/device-run.sh OUTDIR [SECONDS].
# Environment: BIN, the folder of the Release binaries (default build).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
dir=${1:-$here/../.dev}
bin=${BIN:-$here/../build}
bins="pdt bench_parallel bench_peers bench_refine bench_submit"
if ! grep -q '^PDT_ALLOCATOR:[A-Z]*=pool' "$bin/CMakeCache.txt" 2>/dev/null ||
   ! grep -q '^CMAKE_BUILD_TYPE:[A-Z]*=Release' "$bin/CMakeCache.txt" 2>/dev/null; then
  echo "$0: $bin is not a Release build of the pool allocator (the README's tables are)" >&2
  exit 2
fi
# The binaries must be the checkout's: built or brought up to date first (nothing to do if they are).
cmake --build "$bin" --target $bins >/dev/null
rm -rf "$dir/bin" "$dir/lib" "$dir/lib.tar.xz" "$dir/run"
mkdir -p "$dir/bin" "$dir/lib"
for b in $bins; do cp "$bin/$b" "$dir/bin/"; done
for b in $bins; do ldd "$bin/$b"; done | awk '$3 ~ /^\// {print $3}' | sort -u |
  grep -v -E '/(libc|libm|libpthread|libdl|librt|libresolv)\.so|/ld-linux' |
  while read -r lib; do cp -L "$lib" "$dir/lib/"; done
tar -C "$dir" -cf - lib | xz -T0 -6 > "$dir/lib.tar.xz"
rm -rf "$dir/lib"
commit=$(git -C "$here/.." rev-parse --short HEAD 2>/dev/null || echo unknown)
git -C "$here/.." diff --quiet HEAD 2>/dev/null || commit="$commit (with uncommitted changes)"
echo "$commit" > "$dir/COMMIT"
echo "$0: packed $(ls "$dir/bin" | wc -w) binaries of commit $commit and $(tar -tJf "$dir/lib.tar.xz" | grep -c '\.so') libraries into $dir ($(du -sh "$dir" | cut -f1))" >&2
