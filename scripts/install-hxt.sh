#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Makes HXT (gmsh's parallel Delaunay) available to bench_peers, from Debian 12
# packages only. Nothing else uses it: not libpdt, not the tests, not the tool.
#   1. installs libgmsh-dev (HXT is compiled into libgmsh; with OpenCASCADE,
#      FLTK and the rest it adds about 180 MB, hence a script of its own
#      rather than install-deps.sh);
#   2. unpacks gmsh's Debian source package of the very same version into
#      build-hxt-deps/ (HXT's headers, contrib/hxt, are not packaged; its
#      structs must match the library), adding a deb-src entry when none is
#      configured (scripts/lib/deb_src.sh).
# Then re-run cmake: cmake/PdtHxt.cmake finds build-hxt-deps/gmsh-*/ by itself
# (or pass -DPDT_HXT_SOURCE_DIR=that directory) and bench_peers says
# "HXT: gmsh 4.8.4's (libgmsh)" instead of "HXT: not available".
# Idempotent; uses sudo for apt only when not root. gmsh and HXT are GPL (as
# CGAL's Triangulation_3, which the benches link): bench executables only.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
. scripts/lib/steps.sh
steps_init install-hxt
fail() {
  echo "install-hxt: $*" >&2
  exit 1
}
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
install_packages() {
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "$@"
}

if ! installed libgmsh-dev; then step "install libgmsh-dev (HXT inside libgmsh)" install_packages libgmsh-dev; fi
if ! installed dpkg-dev; then step "install dpkg-dev (apt-get source unpacks with dpkg-source)" install_packages dpkg-dev; fi
version=$(dpkg-query -W -f='${Version}' libgmsh-dev)
echo "install-hxt: libgmsh-dev $version -> source package gmsh=$version"

dest=build-hxt-deps
if [ -n "$(find "$dest" -mindepth 2 -maxdepth 2 -name .pdt-gmsh-version 2>/dev/null -exec grep -lxF "$version" {} +)" ]; then
  echo "install-hxt: gmsh $version's source is already in $dest/"
  exit 0
fi

have_source() { apt-cache showsrc --only-source gmsh 2>/dev/null | grep -qxF "Version: $version"; }
if ! have_source; then
  . scripts/lib/deb_src.sh
  step "make Debian's source packages available (deb-src)" add_deb_src "install-hxt.sh (gmsh)"
  step "update the package lists" $SUDO apt-get update -q
  have_source || fail "apt knows no source for gmsh $version (apt-cache showsrc gmsh)"
fi

rm -rf "$dest"
mkdir -p "$dest"
# apt-get source unpacks with dpkg-source, which applies Debian's patches.
step "fetch and unpack gmsh $version's source (about 16 MB)" \
  bash -c "cd '$dest' && apt-get source -q 'gmsh=$version'"
src=$(find "$dest" -mindepth 1 -maxdepth 1 -type d -name 'gmsh-*' | head -n 1)
[ -n "$src" ] && [ -f "$src/contrib/hxt/tetMesh/include/hxt_tetDelaunay.h" ] ||
  fail "no contrib/hxt/tetMesh/include/hxt_tetDelaunay.h under $dest/gmsh-*"
rm -f "$dest"/gmsh_*  # the downloaded archives: the unpacked tree is what counts
echo "$version" > "$src/.pdt-gmsh-version"
steps_done
echo
echo "install-hxt: HXT headers in $src; now re-run cmake (e.g. cmake -S . -B build) and build bench_peers"
