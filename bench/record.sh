#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Runs one benchmark and writes its output under a header that says how it was
# made, as every file in bench/results/ starts:
#   # command: ...
#   # <build type> (<allocator> allocator build), commit <hash>, <date>; machine: ...
#   # load average at start: ...
# Usage: bench/record.sh OUT.txt BENCH [ARGS...]
#   e.g. bench/record.sh bench/results/peers-1M-2cores-intel.txt \
#          build/bench_peers --points 1000000 --threads 1,2 --repeat 3 \
#          --csv bench/results/peers-1M-2cores-intel.csv
# The bench's exit status is the script's; the file holds what it printed either way.
# Where the checkout has no git (a copy run on another machine), PDT_RECORD_COMMIT names
# the commit the binaries were built from; PDT_RECORD_NOTE adds a remark to the header
# (e.g. where the binaries and their libraries came from).
set -uo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 OUT.txt BENCH [ARGS...]" >&2
  exit 2
fi
out=$1
shift
bench=$1
if [ ! -x "$bench" ]; then
  echo "$0: $bench is not an executable (build it first: cmake --build --preset release)" >&2
  exit 2
fi
build_dir=$(dirname "$bench")
allocator=pool
build_type=Release
if [ -f "$build_dir/CMakeCache.txt" ]; then
  allocator=$(sed -n 's/^PDT_ALLOCATOR:[A-Z]*=//p' "$build_dir/CMakeCache.txt")
  build_type=$(sed -n 's/^CMAKE_BUILD_TYPE:[A-Z]*=//p' "$build_dir/CMakeCache.txt")
fi
if [ -n "${PDT_RECORD_COMMIT:-}" ]; then
  commit=$PDT_RECORD_COMMIT
else
  commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
  git diff --quiet HEAD 2>/dev/null || commit="$commit (with uncommitted changes)"
fi
model=$(lscpu | sed -n 's/^Model name:[[:space:]]*//p')
model_number=$(lscpu | sed -n 's/^Model:[[:space:]]*//p')
hypervisor=$(lscpu | sed -n 's/^Hypervisor vendor:[[:space:]]*//p')
os=$( (. /etc/os-release && echo "$PRETTY_NAME") 2>/dev/null || uname -sr)
machine="machine: nproc $(nproc); Model name: $model (model $model_number${hypervisor:+, $hypervisor})"
machine="$machine; $os"
case "$(basename "$bench")" in
  bench_peers)
    gmsh=$(dpkg-query -W -f='${Version}' libgmsh4.8 2>/dev/null || true)
    [ -n "$gmsh" ] && machine="$machine; libgmsh $gmsh (HXT headers: scripts/install-hxt.sh)"
    ;;
esac
mkdir -p "$(dirname "$out")"
{
  echo "# command: $*"
  echo "# ${build_type:-Release} (${allocator:-pool} allocator build), commit $commit, $(date +%F); $machine"
  [ -n "${PDT_RECORD_NOTE:-}" ] && echo "# $PDT_RECORD_NOTE"
  echo "# load average at start: $(cut -d' ' -f1-3 /proc/loadavg | sed 's/ /, /g')"
} > "$out"
"$@" >> "$out" 2>&1
status=$?
echo "$0: wrote $out (exit status $status)" >&2
exit $status
