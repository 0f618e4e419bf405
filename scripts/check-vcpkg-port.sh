#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Pre-release check of the vcpkg port, ports/pdt. Not part of CI: about 10 minutes on
# 2 cores, plus 3-8 minutes the first time to build vcpkg itself.
#
#   scripts/check-vcpkg-port.sh [--lint-only] [WORKDIR]     (default WORKDIR: build-vcpkg/work)
#
# 1. Lints ports/pdt/vcpkg.json against the sources the port builds (lib/, include/):
#    every `#include <boost/LIB/...>` needs a boost-LIB dependency, because vcpkg's
#    boost-headers port installs no library's headers. The stubs below cannot catch a
#    missing one (Debian's libboost-dev has all of Boost), so this check does. It also
#    wants a license and the version of CMakeLists.txt's project().
# 2. Gets vcpkg: $VCPKG_ROOT/vcpkg when VCPKG_ROOT is set, otherwise one built from
#    ../shared/vendor/vcpkg-offline.tar.xz (PDT_VCPKG_VENDOR overrides the path) and
#    kept in build-vcpkg/ for the next run.
# 3. For each variant, `vcpkg install`s pdt from this working tree (uncommitted changes
#    included) with stub ports for the third-party dependencies (empty packages: the
#    build finds the system's CGAL, oneTBB, Boost, zlib and mimalloc), checks the
#    installed tree, and builds and runs tests/package/consumer against it with CMake
#    (vcpkg's toolchain) and with pkg-config, in each build type the triplet installs.
#    What the stubs cannot test: vcpkg's own builds of the dependencies.
#
# Environment (optional):
#   VCPKG_ROOT         an existing vcpkg root with the vcpkg executable built in it
#   PDT_VCPKG_VENDOR   the offline vcpkg tarball (default ../shared/vendor/vcpkg-offline.tar.xz)
#   PDT_PORT_VARIANTS  space-separated NAME=TRIPLET:SPEC list; default (x64 or arm64 host):
#                      release=x64-linux-release:pdt          static, default features (pdt's pool allocator)
#                      mimalloc=x64-linux-release:pdt[mimalloc]  static, the mimalloc feature
#                      shared=x64-linux-dynamic:pdt           shared library, Release and Debug
#   JOBS               parallel jobs (default 2); everything runs under nice -n 10
# Needs: git cmake ninja c++ python3 pkg-config patchelf (vcpkg fixes ELF RPATHs and cannot
# download patchelf offline), and the dependencies' Debian packages (scripts/install-deps.sh).
# Exit status 0 only if every check passes; the last line says PASS or FAIL.
set -uo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
LINT_ONLY=0
if [ "${1:-}" = "--lint-only" ]; then LINT_ONLY=1; shift; fi
case "${1:-}" in -h|--help) sed -n '2,/^set -uo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0;; esac
WORK=${1:-$REPO/build-vcpkg/work}
JOBS=${JOBS:-2}
NICE=(nice -n 10)
T0=$(date +%s)

RESULTS=()
FAILS=0
say()  { echo "check-vcpkg-port: $*"; }
ok()   { RESULTS+=("ok    $*"); echo "  ok    $*"; }
bad()  { RESULTS+=("FAIL  $*"); echo "  FAIL  $*"; FAILS=$((FAILS + 1)); }
finish() {
  echo
  say "summary ($(( $(date +%s) - T0 )) s in all):"
  printf '  %s\n' "${RESULTS[@]}"
  if [ "$FAILS" -eq 0 ]; then say "PASS"; exit 0; fi
  say "FAIL ($FAILS check(s) failed)"; exit 1
}
abort() { bad "$*"; finish; }
elapsed() { echo "$(( $(date +%s) - $1 )) s"; }
show_log() { echo "    --- last lines of $1"; tail -n "${2:-25}" "$1" | sed 's/^/    | /'; }

# --- 1. lint ports/pdt/vcpkg.json ------------------------------------------------------------
say "1. ports/pdt/vcpkg.json against the sources the port builds"
LINT_OUT=$(python3 - "$REPO" <<'EOF'
import json, os, re, sys
repo = sys.argv[1]
port = json.load(open(os.path.join(repo, "ports/pdt/vcpkg.json")))
def names(deps):
    return {d if isinstance(d, str) else d["name"] for d in deps}
top = names(port.get("dependencies", []))
features = {f: names(v.get("dependencies", [])) for f, v in port.get("features", {}).items()}
out = []
def ok(msg):  out.append("ok\t" + msg)
def bad(msg): out.append("FAIL\t" + msg)
def warn(msg): out.append("WARN\t" + msg)

lic = port.get("license")
(ok if isinstance(lic, str) and lic.strip() else bad)(f"license: {json.dumps(lic)}")
cml = open(os.path.join(repo, "CMakeLists.txt")).read()
m = re.search(r"project\(\s*pdt\s+VERSION\s+([0-9.]+)", cml)
ver = port.get("version") or port.get("version-semver") or port.get("version-string")
if m and ver == m.group(1):
    ok(f"version {ver} = CMakeLists.txt's project(pdt VERSION {m.group(1)})")
else:
    bad(f"version {ver} != CMakeLists.txt's project(pdt VERSION {m.group(1) if m else '?'})")

# Boost headers by port. vcpkg's port is boost-<dir> (underscores as dashes) for
# boost/<dir>/..., except for these directories:
PORT_OF = {"archive": "serialization", "concept": "concept-check",
           "functional/hash": "container-hash", "numeric/conversion": "numeric-conversion",
           "numeric/interval": "interval", "numeric/ublas": "ublas", "numeric/odeint": "odeint"}
inc = re.compile(r'^\s*#\s*include\s*[<"]boost/([^>"]+)[>"]')
need, toplevel = {}, {}
dirs = [d for d in ("lib", "include", "src") if os.path.isdir(os.path.join(repo, d))]
for d in dirs:
    for root, _, files in os.walk(os.path.join(repo, d)):
        for f in files:
            path = os.path.join(root, f)
            rel = os.path.relpath(path, repo)
            try:
                lines = open(path, encoding="utf-8", errors="replace").read().splitlines()
            except OSError:
                continue
            for line in lines:
                m = inc.match(line)
                if not m:
                    continue
                parts = m.group(1).split("/")
                if len(parts) == 1:
                    toplevel.setdefault("boost/" + parts[0], set()).add(rel)
                    continue
                key = parts[0] + "/" + re.sub(r"\.hp*$", "", parts[1])
                sub = PORT_OF.get(key) or PORT_OF.get(parts[0]) or parts[0].replace("_", "-")
                need.setdefault("boost-" + sub, {}).setdefault("boost/" + m.group(1), set()).add(rel)
out.append(f"INFO\tscanned {', '.join(d + '/' for d in dirs)} for #include <boost/...>")
for dep, headers in sorted(need.items()):
    hdr = ", ".join(f"<{h}> ({', '.join(sorted(w))})" for h, w in sorted(headers.items()))
    if dep in top:
        ok(f"{hdr} -> dependency {dep}")
    else:
        in_features = [f for f, deps in features.items() if dep in deps]
        extra = f" (only in feature {', '.join(in_features)}; the core build includes it)" if in_features else ""
        bad(f"{hdr} but no {dep} dependency{extra}: a real vcpkg build fails, "
            f"vcpkg's boost-headers has no library headers (another port? add it to PORT_OF in this script)")
if not need:
    out.append("INFO\tno boost/<lib>/ includes")
for hdr, where in sorted(toplevel.items()):
    warn(f"<{hdr}> ({', '.join(sorted(where))}): a top-level Boost header; check by hand which boost-* port has it")
used = set(need)
for dep in sorted(d for d in top if d.startswith("boost-") and d != "boost-headers" and d not in used):
    warn(f"dependency {dep} but no boost/ include needs it any more (stale?)")
print("\n".join(out))
EOF
) || abort "lint: cannot read ports/pdt/vcpkg.json or CMakeLists.txt"
while IFS=$'\t' read -r kind msg; do
  case "$kind" in
    ok)   ok "lint: $msg";;
    FAIL) bad "lint: $msg";;
    WARN) RESULTS+=("WARN  lint: $msg"); echo "  WARN  lint: $msg";;
    *)    echo "        $msg";;
  esac
done <<< "$LINT_OUT"
[ "$LINT_ONLY" = 1 ] && finish

# --- 2. vcpkg ----------------------------------------------------------------------------------
say "2. vcpkg"
# Every missing prerequisite named at once, each with its Debian package, rather than
# one per run.
missing=() packages=()
need() {  # need WHAT PACKAGE TEST...
  local what=$1 package=$2; shift 2
  "$@" >/dev/null 2>&1 || { missing+=("$what"); packages+=("$package"); }
}
abort_if_missing() {
  [ ${#missing[@]} -eq 0 ] && return
  local list
  list=$(IFS=,; echo "${missing[*]}")
  abort "missing: ${list//,/, } (Debian: apt-get install ${packages[*]})"
}
need git git command -v git
need cmake cmake command -v cmake
need ninja ninja-build command -v ninja
need c++ g++ command -v c++
need python3 python3 command -v python3
need pkg-config pkg-config command -v pkg-config
need patchelf patchelf command -v patchelf
if [ -z "${VCPKG_ROOT:-}" ] && [ ! -x "$REPO/build-vcpkg/vcpkg-offline/vcpkg/vcpkg" ]; then
  # vcpkg will be built from the vendored sources: its prerequisites too, in the same list.
  need "libcurl's headers" libcurl4-openssl-dev pkg-config --exists libcurl
  need zip zip command -v zip
  need unzip unzip command -v unzip
fi
abort_if_missing
if [ -n "${VCPKG_ROOT:-}" ]; then
  VCPKG_ROOT=$(cd "$VCPKG_ROOT" 2>/dev/null && pwd) || abort "VCPKG_ROOT=$VCPKG_ROOT: no such directory"
  [ -f "$VCPKG_ROOT/.vcpkg-root" ] && [ -x "$VCPKG_ROOT/vcpkg" ] \
    || abort "VCPKG_ROOT=$VCPKG_ROOT is not a vcpkg root with a built vcpkg executable"
  ok "vcpkg from VCPKG_ROOT=$VCPKG_ROOT"
else
  TARBALL=${PDT_VCPKG_VENDOR:-$REPO/../shared/vendor/vcpkg-offline.tar.xz}
  [ -f "$TARBALL" ] || abort "VCPKG_ROOT is not set and there is no $TARBALL to build vcpkg from"
  TARBALL=$(cd "$(dirname "$TARBALL")" && pwd)/$(basename "$TARBALL")
  CACHE=$REPO/build-vcpkg
  OFFLINE=$CACHE/vcpkg-offline
  sum=$(sha256sum "$TARBALL" | cut -d' ' -f1)
  if [ -x "$OFFLINE/vcpkg/vcpkg" ] && [ "$(cat "$OFFLINE/.pdt-tarball-sha256" 2>/dev/null)" = "$sum" ]; then
    ok "vcpkg built before from $TARBALL ($OFFLINE)"
  else
    # RECIPE.sh apt-installs what it misses; say what is missing instead of becoming root here.
    need "libcurl's headers" libcurl4-openssl-dev pkg-config --exists libcurl
    need zip zip command -v zip
    need unzip unzip command -v unzip
    abort_if_missing
    say "building vcpkg from $TARBALL (3-8 min; log $CACHE/vcpkg-build.log)"
    t=$(date +%s)
    rm -rf "$OFFLINE"; mkdir -p "$CACHE"
    if tar -xJf "$TARBALL" -C "$CACHE" && [ -x "$OFFLINE/RECIPE.sh" ] \
       && "${NICE[@]}" "$OFFLINE/RECIPE.sh" > "$CACHE/vcpkg-build.log" 2>&1 && [ -x "$OFFLINE/vcpkg/vcpkg" ]; then
      echo "$sum" > "$OFFLINE/.pdt-tarball-sha256"
      ok "vcpkg built from $TARBALL ($(elapsed "$t"))"
    else
      show_log "$CACHE/vcpkg-build.log"; abort "building vcpkg from $TARBALL"
    fi
  fi
  VCPKG_ROOT=$OFFLINE/vcpkg
fi
VCPKG=$VCPKG_ROOT/vcpkg
say "vcpkg $("$VCPKG" version 2>/dev/null | head -1 | sed 's/.*version //')"

# pkgconfig_consumer PCDIR EXE: tests/package/consumer built with `pkg-config --cflags --libs pdt`
# (a subshell, so PKG_CONFIG_PATH stays as it was).
pkgconfig_consumer() (
  local flags libdir args
  export PKG_CONFIG_PATH="$1${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}"
  flags=$(pkg-config --cflags --libs pdt) && libdir=$(pkg-config --variable=libdir pdt) || return 1
  echo "pkg-config --cflags --libs pdt: $flags"
  read -r -a args <<< "$flags"
  "${NICE[@]}" c++ -std=c++20 "$SRC/tests/package/consumer/main.cpp" -o "$2" "${args[@]}" -Wl,-rpath,"$libdir" \
    && "$2"
)

# --- 3. install each variant and build consumers against it -------------------------------------
say "3. vcpkg install and consumers (work dir $WORK)"
case "$(uname -m)" in
  x86_64|amd64) ARCH=x64;;
  aarch64|arm64) ARCH=arm64;;
  *) abort "no vcpkg Linux triplet for $(uname -m)";;
esac
VARIANTS=${PDT_PORT_VARIANTS:-"release=$ARCH-linux-release:pdt mimalloc=$ARCH-linux-release:pdt[mimalloc] shared=$ARCH-linux-dynamic:pdt"}

mkdir -p "$WORK" && WORK=$(cd "$WORK" && pwd)
# A snapshot of the working tree: what git would put in a release (tracked and untracked,
# not ignored files), so the port never sees build trees, and uncommitted changes count.
SRC=$WORK/src
rm -rf "$SRC" "$WORK/stubs"; mkdir -p "$SRC"
git -C "$REPO" ls-files -z --cached --others --exclude-standard \
  | tar -C "$REPO" --null -T - --ignore-failed-read -cf - 2>/dev/null | tar -C "$SRC" -xf - \
  || abort "cannot copy the working tree to $SRC"
ok "snapshot of the working tree at $(git -C "$REPO" log -1 --format=%h)$([ -n "$(git -C "$REPO" status --porcelain)" ] && echo ' + uncommitted changes') -> $SRC"

# A stub port (an empty package) for each third-party dependency; vcpkg's own helper ports stay.
read -r PORT_VERSION DEPS < <(python3 - "$SRC/ports/pdt/vcpkg.json" <<'EOF'
import json, sys
j = json.load(open(sys.argv[1]))
deps = set()
for lst in [j.get("dependencies", [])] + [f.get("dependencies", []) for f in j.get("features", {}).values()]:
    deps |= {d if isinstance(d, str) else d["name"] for d in lst}
print(j.get("version") or j.get("version-semver") or j.get("version-string"), " ".join(sorted(deps)))
EOF
)
stubbed=()
for d in $DEPS; do
  case "$d" in vcpkg-*) continue;; esac
  mkdir -p "$WORK/stubs/$d"
  printf '{\n  "name": "%s",\n  "version-string": "system",\n  "description": "Stub: the system package is used"\n}\n' "$d" \
    > "$WORK/stubs/$d/vcpkg.json"
  echo 'set(VCPKG_POLICY_EMPTY_PACKAGE enabled)' > "$WORK/stubs/$d/portfile.cmake"
  stubbed+=("$d")
done
ok "port pdt $PORT_VERSION; stub ports for ${stubbed[*]}"

export VCPKG_ROOT VCPKG_FORCE_SYSTEM_BINARIES=1 VCPKG_DISABLE_METRICS=1 VCPKG_MAX_CONCURRENCY=$JOBS
export PDT_SOURCE_DIR=$SRC   # the portfile builds this tree instead of downloading a release
cd "$WORK" || abort "cd $WORK"

for v in $VARIANTS; do
  name=${v%%=*}; rest=${v#*=}; triplet=${rest%%:*}; spec=${rest#*:}
  dir=$WORK/$name; inst=$dir/installed; tree=$inst/$triplet
  rm -rf "$dir"; mkdir -p "$dir"
  echo
  say "[$name] vcpkg install $spec --triplet=$triplet"
  t=$(date +%s)
  if ! "${NICE[@]}" "$VCPKG" install "$spec" --classic --triplet="$triplet" --binarysource=clear \
        --overlay-ports="$SRC/ports" --overlay-ports="$WORK/stubs" \
        --x-install-root="$inst" --x-buildtrees-root="$dir/buildtrees" \
        --x-packages-root="$dir/packages" --downloads-root="$WORK/downloads" > "$dir/install.log" 2>&1; then
    show_log "$dir/install.log"
    for f in "$dir"/buildtrees/pdt/*-err.log; do [ -s "$f" ] && show_log "$f"; done
    bad "[$name] vcpkg install $spec --triplet=$triplet ($(elapsed "$t"); log $dir/install.log)"
    continue
  fi
  ok "[$name] vcpkg install $spec --triplet=$triplet ($(elapsed "$t"))"

  # The installed tree.
  build_types=Release
  grep -qs 'VCPKG_BUILD_TYPE[[:space:]]*release' "$VCPKG_ROOT/triplets/$triplet.cmake" \
    "$VCPKG_ROOT/triplets/community/$triplet.cmake" || build_types="Release Debug"
  if grep -qs 'VCPKG_LIBRARY_LINKAGE[[:space:]]*dynamic' "$VCPKG_ROOT/triplets/$triplet.cmake" \
       "$VCPKG_ROOT/triplets/community/$triplet.cmake"; then linkage=shared; else linkage=static; fi
  case "$spec" in *mimalloc*) alloc=mimalloc;; *) alloc=pool;; esac
  missing=()
  for f in include/pdt/pdt.hpp share/pdt/pdtConfig.cmake share/pdt/pdtTargets.cmake share/pdt/copyright \
           share/pdt/usage lib/pkgconfig/pdt.pc; do
    [ -f "$tree/$f" ] || missing+=("$f")
  done
  [[ $build_types == *Debug* ]] && { [ -f "$tree/debug/lib/pkgconfig/pdt.pc" ] || missing+=(debug/lib/pkgconfig/pdt.pc); }
  for d in lib $([[ $build_types == *Debug* ]] && echo debug/lib); do
    if [ $linkage = shared ]; then
      ls "$tree/$d"/libpdt.so* >/dev/null 2>&1 || missing+=("$d/libpdt.so")
      [ -e "$tree/$d/libpdt.a" ] && missing+=("(unexpected) $d/libpdt.a")
    else
      [ -f "$tree/$d/libpdt.a" ] || missing+=("$d/libpdt.a")
      ls "$tree/$d"/libpdt.so* >/dev/null 2>&1 && missing+=("(unexpected) $d/libpdt.so")
    fi
  done
  got_alloc=$(sed -n 's/^set(pdt_ALLOCATOR "\(.*\)")$/\1/p' "$tree/share/pdt/pdtConfig.cmake" 2>/dev/null)
  [ "$got_alloc" = "$alloc" ] || missing+=("pdtConfig.cmake says allocator '$got_alloc', not $alloc")
  if [ ${#missing[@]} -eq 0 ]; then
    ok "[$name] installed tree: $linkage libpdt ($build_types), allocator $alloc, headers, CMake package, pdt.pc, copyright, usage"
  else
    bad "[$name] installed tree: ${missing[*]}"
  fi

  for bt in $build_types; do
    # CMake consumer, through vcpkg's toolchain.
    b=$dir/consumer-cmake-$bt; log=$b.log
    t=$(date +%s)
    if "${NICE[@]}" cmake -S "$SRC/tests/package/consumer" -B "$b" -G Ninja -DCMAKE_BUILD_TYPE="$bt" \
         -DCMAKE_TOOLCHAIN_FILE="$VCPKG_ROOT/scripts/buildsystems/vcpkg.cmake" \
         -DVCPKG_TARGET_TRIPLET="$triplet" -DVCPKG_INSTALLED_DIR="$inst" -DVCPKG_MANIFEST_MODE=OFF \
         -DEXPECTED_VERSION="$PORT_VERSION" > "$log" 2>&1 \
       && "${NICE[@]}" cmake --build "$b" -j "$JOBS" >> "$log" 2>&1 \
       && "$b/pdt_consumer" >> "$log" 2>&1; then
      ok "[$name] CMake consumer, $bt: find_package(pdt) + pdt::pdt, built and ran ($(elapsed "$t"))"
    else
      show_log "$log"; bad "[$name] CMake consumer, $bt (log $log)"
    fi

    # pkg-config consumer, with the .pc vcpkg installed for this build type.
    pcdir=$tree/lib/pkgconfig; [ "$bt" = Debug ] && pcdir=$tree/debug/lib/pkgconfig
    exe=$dir/consumer-pkgconfig-$bt; log=$exe.log
    t=$(date +%s)
    if pkgconfig_consumer "$pcdir" "$exe" > "$log" 2>&1; then
      ok "[$name] pkg-config consumer, $bt: c++ main.cpp \$(pkg-config --cflags --libs pdt), built and ran ($(elapsed "$t"))"
      sed -n 's/^pkg-config --cflags --libs pdt: /          pkg-config --cflags --libs pdt: /p' "$log"
    else
      show_log "$log"; bad "[$name] pkg-config consumer, $bt (log $log)"
    fi
  done
done

finish
