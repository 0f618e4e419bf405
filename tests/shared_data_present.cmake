# SPDX-License-Identifier: MIT
# data.shared_present: reports whether the optional real point sets are there.
if(EXISTS "${DIR}/SOURCES.md")
  file(GLOB_RECURSE _files "${DIR}/*")
  list(LENGTH _files _n)
  message("shared data found: ${DIR} (${_n} files); the [data] tests read it")
else()
  message("SKIPPED: ${DIR} not found: the tests on the real point sets in it (tagged [data]) pass with a "
          "warning and check nothing; data/kitten.xyz (shipped) is still tested. Put the shared data beside the "
          "repository to run them.")
endif()
