#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The 16-core tables of the README (issue 13), each written by bench/record.sh into OUTDIR
# as it finishes. Steps, in the default order:
#   refine       the refiner against CGAL, 1 to 16 workers (torus, size 0.018: 2.6x the
#                tetrahedra of the 2-core table's 0.025, so that 16 workers have work)
#   parallel     1M points one at a time and in batch, 1 to 16 workers (uniform, normal,
#                line), against CGAL sequential and parallel
#   clustered    the clustered streams (clusters, kuzmin), 1 and 16 workers
#   peers        batch against CGAL and HXT, 1, 4 and 16 threads
#   submit       the submitting loop, one at a time (16 workers) and the batch's start (1
#                and 16), bench_submit
#   skewed       the skewed streams with a refiner trace (made first, by pdt refine)
#   interleaved  the interleaved stream, 1M, 1 to 16 workers
# On a machine without our build and dependencies: bench/device-pack.sh here, then
# bench/device-run.sh there.
# Usage: bench/scaling.sh OUTDIR [SECONDS [STEP...]]
#   SECONDS (default 0: no limit) is a deadline for the whole run: a bench that would start
#   with less than a minute left is skipped, one still running at the deadline is stopped
#   (its file keeps what it printed). STEPs (default: all, in the order above) run in the
#   order given, each once, so that what matters most comes first; only the binaries they
#   run need to be built.
# Environment: BIN, the folder of the Release binaries (default build); PDT_RECORD_COMMIT and
# PDT_RECORD_NOTE as for record.sh, when the checkout has no git; SCALING_CHECK_ONLY=1 checks
# the arguments and exits (0 when they are good) without running or looking for binaries.
# On the 16-core machine at c4a9eb1 the steps took: submit 36 s, parallel 301, peers 78,
# refine 28, interleaved 57, skewed about 170 (its trace included), clustered 99.
set -u
if [ $# -lt 1 ]; then
  echo "usage: $0 OUTDIR [SECONDS [STEP...]]" >&2
  exit 2
fi
out=$1
limit=${2:-0}
if ! [[ $limit =~ ^[0-9]+$ ]]; then
  echo "$0: SECONDS must be a whole number of seconds (0: no limit), not '$limit'" >&2
  exit 2
fi
shift $(($# >= 2 ? 2 : 1))
steps=""  # each step once, in the order first given
needed=""  # the binaries those steps run
for s in ${*:-refine parallel clustered peers submit skewed interleaved}; do
  case $s in
    refine) needed="$needed bench_refine" ;;
    parallel | clustered | interleaved) needed="$needed bench_parallel" ;;
    peers) needed="$needed bench_peers" ;;
    submit) needed="$needed bench_submit" ;;
    skewed) needed="$needed bench_parallel pdt" ;;
    *)
      echo "$0: unknown step '$s' (refine, parallel, clustered, peers, submit, skewed, interleaved)" >&2
      exit 2
      ;;
  esac
  case " $steps " in
    *" $s "*) ;;
    *) steps="$steps $s" ;;
  esac
done
[ "${SCALING_CHECK_ONLY:-0}" = 1 ] && exit 0
here=$(cd "$(dirname "$0")" && pwd)
bin=${BIN:-$here/../build}
for b in $needed; do
  if [ ! -x "$bin/$b" ]; then
    echo "$0: $bin/$b is not built (cmake --build --preset release)" >&2
    exit 2
  fi
done
mkdir -p "$out"
start=$(date +%s)
status=0
left=0  # seconds to the deadline (0: none), set by time_left
time_left() {  # NAME: false, and says so, when less than a minute is left
  left=0
  [ "$limit" -gt 0 ] || return 0
  left=$((start + limit - $(date +%s)))
  if [ $left -lt 60 ]; then
    echo "$0: skipped $1 ($left s left)" >&2
    status=1
    return 1
  fi
}
step() {  # OUT.txt BENCH ARGS...
  time_left "$1" || return 0
  timeout "$left" bash "$here/record.sh" "$@" || status=1
}
for s in $steps; do
  case $s in
    refine)
      step "$out/refine-torus-16cores.txt" "$bin/bench_refine" --domain torus --size 0.018 --threads 1,2,4,8,16
      ;;
    parallel)
      step "$out/parallel-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 \
        --threads 1,2,4,8,16 --dists uniform,normal,line --timeout 120 --csv "$out/parallel-1M-16cores.csv"
      ;;
    clustered)
      step "$out/clustered-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 --threads 1,16 \
        --dists clusters,kuzmin --skip-cgal-parallel --timeout 120 --csv "$out/clustered-1M-16cores.csv"
      ;;
    peers)
      step "$out/peers-1M-16cores.txt" "$bin/bench_peers" --points 1000000 --dists uniform,normal \
        --threads 1,4,16 --timeout 120 --csv "$out/peers-1M-16cores.csv"
      ;;
    submit)
      step "$out/submit-1M-16cores.txt" "$bin/bench_submit" --points 1000000 --threads 16 --repeat 3
      step "$out/submit-batch-1M-16cores.txt" "$bin/bench_submit" --points 1000000 --threads 1,16 --batch --repeat 3
      ;;
    skewed)
      trace=$out/torus.ops
      if [ ! -s "$trace" ]; then
        time_left "$out/skewed-300k-16cores.txt" || continue
        # Exit status 1 (a bound missed, unfinished) still writes the trace.
        timeout "$left" "$bin/pdt" refine --domain torus --size 0.022 --threads 2 --trace "$trace" > /dev/null
      fi
      if [ -s "$trace" ]; then
        step "$out/skewed-300k-16cores.txt" "$bin/bench_parallel" --points 300000 --threads 1,4,16 \
          --dists none --skewed --trace "$trace" --timeout 60 --csv "$out/skewed-300k-16cores.csv"
      else
        echo "$0: pdt refine wrote no trace $trace; skewed skipped" >&2
        status=1
      fi
      ;;
    interleaved)
      step "$out/interleaved-1M-16cores.txt" "$bin/bench_parallel" --points 1000000 \
        --threads 1,2,4,8,16 --dists uniform --skip-main --interleaved --timeout 120 \
        --csv "$out/interleaved-1M-16cores.csv"
      ;;
  esac
done
exit $status
