# SPDX-License-Identifier: MIT
# HXT (gmsh's parallel Delaunay, Marot et al. 2019) for bench_peers only: never
# for libpdt, its tests or its tools. gmsh is GPL, as CGAL's Triangulation_3 the
# benches already link. Debian ships HXT inside libgmsh (libgmsh-dev) but not
# its headers; those come from gmsh's Debian source package of the same
# version (scripts/install-hxt.sh installs the one and unpacks the other into
# build-hxt-deps/). HXT is used when
#   - libgmsh is found, and OpenMP (HXT's threads: bench_peers sets their number),
#   - PDT_HXT_SOURCE_DIR (a gmsh source tree) holds contrib/hxt's headers; when
#     empty, build-hxt-deps/gmsh-*/ is looked at,
#   - that tree's version (its CMakeLists.txt) is the library's (its file name):
#     HXTMesh and HXTDelaunayOptions are plain structs, so the headers must match.
# Otherwise bench_peers builds without HXT and says so when it runs.
# Sets PDT_HXT_FOUND, PDT_HXT_INCLUDE_DIRS, PDT_HXT_LIBRARIES, PDT_HXT_VERSION.
set(PDT_HXT_SOURCE_DIR "" CACHE PATH
    "gmsh source tree whose contrib/hxt headers match the installed libgmsh (bench_peers' HXT); empty: build-hxt-deps/gmsh-*")
set(PDT_HXT_FOUND FALSE)
set(_pdt_hxt_why "")

set(_pdt_hxt_src "${PDT_HXT_SOURCE_DIR}")
if(NOT _pdt_hxt_src)
  file(GLOB _pdt_hxt_candidates LIST_DIRECTORIES true "${PROJECT_SOURCE_DIR}/build-hxt-deps/gmsh-*")
  foreach(_c ${_pdt_hxt_candidates})
    if(EXISTS "${_c}/contrib/hxt/tetMesh/include/hxt_tetDelaunay.h")
      set(_pdt_hxt_src "${_c}")
    endif()
  endforeach()
endif()

find_library(PDT_GMSH_LIBRARY NAMES gmsh)
find_package(OpenMP COMPONENTS CXX QUIET)
if(NOT PDT_GMSH_LIBRARY)
  set(_pdt_hxt_why "no libgmsh (apt-get install libgmsh-dev)")
elseif(NOT OpenMP_CXX_FOUND)
  set(_pdt_hxt_why "no OpenMP for C++")
elseif(NOT _pdt_hxt_src OR NOT EXISTS "${_pdt_hxt_src}/contrib/hxt/tetMesh/include/hxt_tetDelaunay.h")
  set(_pdt_hxt_why "no HXT headers (set PDT_HXT_SOURCE_DIR to a gmsh source tree, or run scripts/install-hxt.sh)")
else()
  # The library's version: its real file name, libgmsh.so.MAJOR.MINOR.PATCH.
  get_filename_component(_pdt_gmsh_real "${PDT_GMSH_LIBRARY}" REALPATH)
  string(REGEX MATCH "[0-9]+\\.[0-9]+\\.[0-9]+$" _pdt_gmsh_lib_version "${_pdt_gmsh_real}")
  # The source's: set(GMSH_MAJOR_VERSION 4) and so on in its CMakeLists.txt.
  file(STRINGS "${_pdt_hxt_src}/CMakeLists.txt" _pdt_gmsh_version_lines
       REGEX "^set\\(GMSH_(MAJOR|MINOR|PATCH)_VERSION [0-9]+\\)")
  set(_pdt_gmsh_src_version "")
  foreach(_part MAJOR MINOR PATCH)
    foreach(_l ${_pdt_gmsh_version_lines})
      if(_l MATCHES "^set\\(GMSH_${_part}_VERSION ([0-9]+)\\)")
        list(APPEND _pdt_gmsh_src_version "${CMAKE_MATCH_1}")
      endif()
    endforeach()
  endforeach()
  string(REPLACE ";" "." _pdt_gmsh_src_version "${_pdt_gmsh_src_version}")
  if(NOT _pdt_gmsh_lib_version OR NOT _pdt_gmsh_lib_version STREQUAL _pdt_gmsh_src_version)
    set(_pdt_hxt_why "libgmsh ${_pdt_gmsh_lib_version} (${_pdt_gmsh_real}) but HXT headers of gmsh ${_pdt_gmsh_src_version} (${_pdt_hxt_src})")
  else()
    set(PDT_HXT_FOUND TRUE)
    set(PDT_HXT_VERSION "${_pdt_gmsh_lib_version}")
    set(PDT_HXT_INCLUDE_DIRS "${_pdt_hxt_src}/contrib/hxt/core/include" "${_pdt_hxt_src}/contrib/hxt/tetMesh/include")
    set(PDT_HXT_LIBRARIES "${PDT_GMSH_LIBRARY}" OpenMP::OpenMP_CXX)
  endif()
endif()

if(PDT_HXT_FOUND)
  message(STATUS "bench_peers: HXT from libgmsh ${PDT_HXT_VERSION}, headers from ${_pdt_hxt_src}")
else()
  message(STATUS "bench_peers: without HXT: ${_pdt_hxt_why}")
endif()
