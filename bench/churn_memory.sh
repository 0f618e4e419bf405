#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Churn memory (issue 10): a refiner-like stream of N insertions with 90% of
# them undone, interleaved (pdt gen --points N --remove-fraction 0.9
# --interleaved; N/10 vertices at the end), replayed by `pdt run` on the
# sequential kernel and on the engine. The engine's peak memory must stay
# within 1.3x the sequential kernel's: bounded by the live mesh and the
# operations in flight, not by the operations ever made. Exit status 1 if not.
#
#   bench/churn_memory.sh [BUILD_DIR] [POINTS] [WORKERS]   (defaults: build 2000000 2)
set -euo pipefail
build=${1:-build}
points=${2:-2000000}
workers=${3:-2}
pdt="$build/pdt"
[[ -x "$pdt" ]] || { echo "churn_memory: no pdt tool at $pdt (build the pdt_tool target)" >&2; exit 2; }
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
stream="$dir/churn.opsb"
echo "churn_memory: $points insertions, 90% undone (interleaved); machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "command: bench/churn_memory.sh $build $points $workers"
"$pdt" gen --points "$points" --remove-fraction 0.9 --interleaved --out "$stream" >/dev/null
for mode in 0 "$workers"; do
  if [[ $mode == 0 ]]; then args=(); else args=(--threads "$mode"); fi
  "$pdt" run "$stream" "${args[@]}" --validate >"$dir/run-$mode.txt"
  grep -q '^validate *ok' "$dir/run-$mode.txt" || { cat "$dir/run-$mode.txt"; echo "churn_memory: not valid" >&2; exit 1; }
  label=$([[ $mode == 0 ]] && echo "sequential kernel" || echo "engine, $mode workers")
  printf '%-20s %s | %s | %s | %s\n' "$label" "$(grep '^mixed time' "$dir/run-$mode.txt")" \
    "$(grep '^peak memory' "$dir/run-$mode.txt")" "$(grep '^bytes/vertex' "$dir/run-$mode.txt")" \
    "$(grep '^vertices' "$dir/run-$mode.txt")"
done
seq_mb=$(awk '/^peak memory/ {print $3}' "$dir/run-0.txt")
eng_mb=$(awk '/^peak memory/ {print $3}' "$dir/run-$workers.txt")
ratio=$(awk -v a="$eng_mb" -v b="$seq_mb" 'BEGIN {printf "%.2f", a / b}')
verdict=$(awk -v r="$ratio" 'BEGIN {print (r <= 1.3) ? "within" : "OVER"}')
echo "engine peak / sequential peak: $ratio ($verdict the 1.3x target)"
[[ $verdict == within ]]
