#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs pdt's build dependencies from Debian 12 packages. Idempotent: packages
# already present are left alone, so it is cheap to run before every build.
#   install-deps.sh            what building and testing need (python3-vtk9 and
#                              python3-numpy, which Debian's VTK bindings use but do not
#                              pull in: the test that reads pdt's .vtu files with VTK's
#                              own reader)
#   install-deps.sh --extras   also what the plot and picture scripts need
#                              (matplotlib, Xvfb for VTK's offscreen rendering)
#                              and the clang preset (clang++)
set -euo pipefail
packages=(build-essential cmake ninja-build pkg-config libtbb-dev libcgal-dev libgmp-dev libmpfr-dev
          libboost-dev libmimalloc-dev catch2 zlib1g-dev python3-vtk9 python3-numpy)
if [ "${1:-}" = "--extras" ]; then packages+=(python3-matplotlib xvfb xauth clang); fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "pdt: all build dependencies are installed"
  exit 0
fi
echo "pdt: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
