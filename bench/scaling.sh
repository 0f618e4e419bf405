#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The 16-core tables of the README (issue 13): the refiner against CGAL (1 to 16 workers),
# 1M-point scaling (uniform, normal, line), the clustered streams (clusters, kuzmin) at 1
# and 16 workers, batch against CGAL and HXT, the skewed streams with a refiner trace, and
# the interleaved stream, each written by bench/record.sh into OUTDIR as it finishes, in
# that order (the first three fit in about 500 s). On a machine without our build and
# dependencies: bench/device-pack.sh here, then bench/device-run.sh there.
# Usage: bench/scaling.sh OUTDIR [SECONDS]
#   SECONDS (default: no limit) is a deadline for the whole run: a bench that would start
#   with less than a minute left is skipped, one still running at the deadline is stopped
#   (its file keeps what it printed).
# Environment: BIN, the folder of the Release binaries (default build); PDT_RECORD_COMMIT and
# PDT_RECORD_NOTE as for record.sh, when the checkout has no git.
# On our 16-core run (f1a4af4) the first three took 360, 83 and 208 s; the interleaved
# stream at 1M did not fit.
set -u
if [ $# -lt 1 ]; then
  echo "usage: $0 OUTDIR [SECONDS]" >&2
  exit 2
fi
out=$1
limit=${2:-0}
here=$(cd "$(dirname "$0")" && pwd)
bin=${BIN:-$here/../build}
for b in bench_parallel bench_peers bench_refine pdt; do
  if [ ! -x "$bin/$b" ]; then
    echo "$0: $bin/$b is not built (cmake --build --preset release)" >&2
    exit 2
  fi
done
mkdir -p "$out"
start=$(date +%s)
status=0
step() {  # OUT.txt BENCH ARGS...
  local left=0
  if [ "$limit" -gt 0 ]; then
    left=$((start + limit - $(date +%s)))
    if [ $left -lt 60 ]; then
      echo "$0: skipped $1 ($left s left)" >&2
      status=1
      return
    fi
  fi
  timeout "$left" bash "$here/record.sh" "$@" || status=1
}
trace=$out/torus.ops
if [ ! -s "$trace" ]; then
  # Exit status 1 (a bound missed, unfinished) still writes the trace.
  "$bin/pdt" refine --domain torus --size 0.022 --threads 2 --trace "$trace" > /dev/null
  if [ ! -s "$trace" ]; then
    echo "$0: pdt refine wrote no trace $trace" >&2
    exit 1
  fi
fi
step "$out/refine-torus-16cores.txt" "$bin/bench_refine" --domain torus --size 0.025 --threads 1,2,4,8,16
step "$out/parallel-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 \
  --threads 1,2,4,8,16 --dists uniform,normal,line --timeout 120 --csv "$out/parallel-1M-16cores.csv"
step "$out/clustered-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 --threads 1,16 \
  --dists clusters,kuzmin --skip-cgal-parallel --timeout 120 --csv "$out/clustered-1M-16cores.csv"
step "$out/peers-1M-16cores.txt" "$bin/bench_peers" --points 1000000 --dists uniform,normal \
  --threads 1,4,16 --timeout 120 --csv "$out/peers-1M-16cores.csv"
step "$out/skewed-300k-16cores.txt" "$bin/bench_parallel" --points 300000 --threads 1,4,16 \
  --dists none --skewed --trace "$trace" --timeout 60 --csv "$out/skewed-300k-16cores.csv"
step "$out/interleaved-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 \
  --threads 1,2,4,8,16 --dists uniform --skip-main --interleaved --timeout 120 \
  --csv "$out/interleaved-1M-16cores.csv"
exit $status
