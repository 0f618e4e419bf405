# SPDX-License-Identifier: MIT
# Sourced by the project's scripts: run named steps, say how long each took,
# and name the step that failed (with set -e a script would otherwise just stop).
#   steps_init NAME   (NAME prefixes the failure line)
#   step "what" command args...
steps_init() {
  steps_name=$1
  current_step=""
  trap 'rc=$?; if [ $rc -ne 0 ]; then echo "$steps_name: FAILED at step: ${current_step:-setup} (exit $rc)" >&2; fi' EXIT
}

step() {
  current_step="$1"
  shift
  echo
  echo "==> $current_step"
  echo "    \$ $*"
  local start=$SECONDS
  "$@"
  echo "==> $current_step: done in $((SECONDS - start)) s"
}

steps_done() { current_step=""; }
