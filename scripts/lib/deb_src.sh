# SPDX-License-Identifier: MIT
# Sourced by the scripts that fetch Debian source packages with `apt-get
# source` (build-tsan-tbb.sh, install-hxt.sh).
#   add_deb_src WHO   when no deb-src entry is configured, adds deb-src twins
#                     of the Debian entries apt already uses (WHO, e.g.
#                     "build-tsan-tbb.sh (onetbb)", goes into the files' first
#                     line). Uses $SUDO and the caller's fail(). The caller
#                     runs `apt-get update` afterwards.

# Active deb-src entries in the classic one-line format or in deb822 .sources files.
deb_src_configured() {
  local f
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [ -f "$f" ] && grep -qE '^[[:space:]]*deb-src[[:space:]]' "$f" && return 0
  done
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -f "$f" ] && grep -qiE '^Types:.*\bdeb-src\b' "$f" && return 0
  done
  return 1
}
# Writes to stdout a deb-src copy of every active Debian entry for this
# release (suites "$codename" and "$codename-*"), in the format of the files
# they come from; third-party repositories are left out.
deb_src_entries_822() {
  local f
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -f "$f" ] || continue
    awk -v codename="$codename" '
      function flush() {
        if (n > 0 && is_deb && !disabled && suite_ok) {
          for (i = 1; i <= n; i++) {
            if (tolower(lines[i]) ~ /^types:/) print "Types: deb-src"; else print lines[i]
          }
          print ""
        }
        n = 0; is_deb = 0; disabled = 0; suite_ok = 0
      }
      /^[[:space:]]*$/ { flush(); next }
      /^#/ { next }
      {
        lines[++n] = $0
        key = tolower($1)
        if (key == "types:") { for (i = 2; i <= NF; i++) if ($i == "deb") is_deb = 1 }
        if (key == "enabled:" && tolower($2) == "no") disabled = 1
        if (key == "suites:") {
          for (i = 2; i <= NF; i++) if ($i == codename || index($i, codename "-") == 1) suite_ok = 1
        }
      }
      END { flush() }' "$f"
  done
}
deb_src_entries_list() {
  local f
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [ -f "$f" ] || continue
    # deb [options] URI suite components...
    sed -nE "s/^[[:space:]]*deb([[:space:]]+(\[[^]]*\]))?[[:space:]]+([^[:space:]]+)[[:space:]]+(${codename}|${codename}-[^[:space:]]+)([[:space:]].*)$/deb-src\1 \3 \4\5/p" "$f"
  done
}

add_deb_src() {
  local who=$1 codename entries_822 entries_list target
  if deb_src_configured; then
    echo "    a deb-src entry is configured; updating the package lists"
    return 0
  fi
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
  [ -n "$codename" ] || fail "no VERSION_CODENAME in /etc/os-release: add a deb-src entry for Debian by hand"
  entries_822=$(deb_src_entries_822)
  entries_list=$(deb_src_entries_list)
  if [ -n "$entries_822" ]; then
    target=/etc/apt/sources.list.d/pdt-deb-src.sources
    echo "    adding $target (deb-src twins of the Debian entries in /etc/apt/sources.list.d/*.sources)"
    printf '# Added by pdt scripts/%s: Debian source packages (apt-get source).\n%s\n' "$who" \
      "$entries_822" | $SUDO tee "$target" > /dev/null
  fi
  if [ -n "$entries_list" ]; then
    target=/etc/apt/sources.list.d/pdt-deb-src.list
    echo "    adding $target (deb-src twins of the Debian lines in sources.list)"
    printf '# Added by pdt scripts/%s: Debian source packages (apt-get source).\n%s\n' "$who" \
      "$entries_list" | $SUDO tee "$target" > /dev/null
  fi
  [ -n "$entries_822$entries_list" ] ||
    fail "found no active Debian '$codename' entry in /etc/apt/sources.list or /etc/apt/sources.list.d/ to derive a deb-src entry from"
}
