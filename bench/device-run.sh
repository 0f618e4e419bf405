#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Runs bench/scaling.sh with the binaries and libraries bench/device-pack.sh packed, on a
# machine that has neither our build nor our dependencies (the lent 16-core one).
# Usage: bench/device-run.sh OUTDIR [SECONDS [STEP...]]    (DEV: the packed folder, default .dev)
# The tables are written in a scratch folder (WORK, default a new one under /tmp) and
# packed into OUTDIR/scaling-results.tar.gz at the end, the refiner trace left out: one
# file, as the lent machine's $OUT takes few. SECONDS and the STEPs are scaling.sh's (its
# deadline, and which tables in which order): give the call a minute more than SECONDS.
set -euo pipefail
if [ $# -lt 1 ]; then
  echo "usage: $0 OUTDIR [SECONDS [STEP...]]" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
dev=${DEV:-$here/../.dev}
if [ ! -f "$dev/lib.tar.xz" ] || [ ! -x "$dev/bin/pdt" ] || [ ! -s "$dev/COMMIT" ]; then
  echo "$0: $dev holds no pack (run bench/device-pack.sh first, and carry $dev)" >&2
  exit 2
fi
# Bad arguments are refused before anything is unpacked.
SCALING_CHECK_ONLY=1 bash "$here/scaling.sh" "$@" || exit 2
[ -d "$dev/lib" ] || tar -C "$dev" -xJf "$dev/lib.tar.xz"
# The carried libraries for our binaries only (wrappers), not for the system's
# tools that the scripts call (lscpu, tar, ...), which have their own.
wrap=$dev/run
mkdir -p "$wrap"
for b in "$dev"/bin/*; do
  missing=$(LD_LIBRARY_PATH="$dev/lib" ldd "$b" | grep 'not found' || true)
  if [ -n "$missing" ]; then
    echo "$0: $b misses libraries here:" >&2
    echo "$missing" >&2
    exit 2
  fi
  printf '#!/bin/sh\nLD_LIBRARY_PATH="%s" exec "%s" "$@"\n' "$dev/lib" "$b" > "$wrap/$(basename "$b")"
  chmod +x "$wrap/$(basename "$b")"
done
export BIN=$wrap
commit=$(cat "$dev/COMMIT")
export PDT_RECORD_COMMIT=${PDT_RECORD_COMMIT:-$commit}
export PDT_RECORD_NOTE=${PDT_RECORD_NOTE:-"lent machine; Release binaries (pool allocator) built on Debian 12 at $commit, with Debian 12's libraries carried beside them (bench/device-pack.sh); stopped at the session's deadline if unfinished"}
out=$1
shift
mkdir -p "$out"
work=${WORK:-$(mktemp -d /tmp/pdt-scaling.XXXXXX)}
mkdir -p "$work"
status=0
bash "$here/scaling.sh" "$work" "$@" || status=$?
tar -C "$work" -czf "$out/scaling-results.tar.gz" --exclude='*.ops' .
echo "$0: the tables are in $out/scaling-results.tar.gz (exit status $status)" >&2
exit $status
