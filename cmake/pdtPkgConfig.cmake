# SPDX-License-Identifier: MIT
# pdt.pc for pkg-config users, installed into <libdir>/pkgconfig beside the CMake package.
# Included from the top CMakeLists.txt inside if(PDT_INSTALL), after target pdt exists.
#
# The file is relocatable: prefix is found from ${pcfiledir}, so it stays right for
# `cmake --install --prefix <elsewhere>` and a moved prefix (vcpkg rewrites it the same way).
#
# Requires: tbb, always: pdt's public headers include oneTBB (as pdt::pdt links TBB::tbb PUBLIC).
# A static libpdt.a also leaves its private dependencies to the consumer's link: GMP and MPFR
# (CGAL's exact predicates), zlib, and mimalloc when PDT_ALLOCATOR=mimalloc. They go in Libs,
# not Libs.private, so that a plain `pkg-config --libs pdt` links; a shared libpdt.so records
# them itself and lists none.
# Empty: <libdir>/pkgconfig, following CMAKE_INSTALL_LIBDIR (as the CMake package's folder).
set(PDT_INSTALL_PKGCONFIGDIR "" CACHE STRING "Where pdt.pc goes (empty: <libdir>/pkgconfig)")
set(pdt_install_pkgconfigdir "${PDT_INSTALL_PKGCONFIGDIR}")
if(pdt_install_pkgconfigdir STREQUAL "")
  set(pdt_install_pkgconfigdir "${CMAKE_INSTALL_LIBDIR}/pkgconfig")
endif()

if(IS_ABSOLUTE "${pdt_install_pkgconfigdir}")
  set(_pdt_pc_prefix "${CMAKE_INSTALL_PREFIX}")  # not relocatable, but what was asked for
else()
  # One ".." per component of the pkgconfig dir: lib/pkgconfig -> ${pcfiledir}/../..
  set(_pdt_pc_prefix "\${pcfiledir}")
  string(REPLACE "/" ";" _pdt_pc_parts "${pdt_install_pkgconfigdir}")
  foreach(_part IN LISTS _pdt_pc_parts)
    if(NOT _part STREQUAL "" AND NOT _part STREQUAL ".")
      string(APPEND _pdt_pc_prefix "/..")
    endif()
  endforeach()
endif()
foreach(_dir LIBDIR INCLUDEDIR)
  if(IS_ABSOLUTE "${CMAKE_INSTALL_${_dir}}")
    set(_pdt_pc_${_dir} "${CMAKE_INSTALL_${_dir}}")
  else()
    set(_pdt_pc_${_dir} "\${prefix}/${CMAKE_INSTALL_${_dir}}")
  endif()
endforeach()

set(_pdt_pc_libs "-L\${libdir} -lpdt")
get_target_property(_pdt_pc_type pdt TYPE)
if(_pdt_pc_type STREQUAL "STATIC_LIBRARY")
  set(_pdt_pc_private mpfr gmp z)  # a static link needs each library before those it uses
  set(_pdt_pc_files ${MPFR_LIBRARIES} ${GMP_LIBRARIES} ${ZLIB_LIBRARIES})
  if(PDT_ALLOCATOR STREQUAL "mimalloc")
    # The library's name as built (e.g. mimalloc-debug in a debug mimalloc), from its file.
    set(_pdt_mi_file "")
    if(CMAKE_BUILD_TYPE)
      string(TOUPPER "${CMAKE_BUILD_TYPE}" _cfg)
      get_target_property(_pdt_mi_file ${PDT_MIMALLOC_TARGET} LOCATION_${_cfg})
    endif()
    if(NOT _pdt_mi_file)
      get_target_property(_pdt_mi_file ${PDT_MIMALLOC_TARGET} LOCATION)
    endif()
    set(_pdt_mi_name mimalloc)
    if(_pdt_mi_file)
      get_filename_component(_name "${_pdt_mi_file}" NAME)
      if(_name MATCHES "^lib(.+)\\.(a|so)(\\.[0-9.]+)?$")
        set(_pdt_mi_name "${CMAKE_MATCH_1}")
      endif()
      list(APPEND _pdt_pc_files "${_pdt_mi_file}")
    endif()
    list(APPEND _pdt_pc_private ${_pdt_mi_name})
  endif()
  # -L for any of them outside the linker's own search path (none on Debian or in vcpkg).
  set(_pdt_pc_dirs "")
  foreach(_file IN LISTS _pdt_pc_files)
    if(IS_ABSOLUTE "${_file}" AND EXISTS "${_file}")
      get_filename_component(_dir "${_file}" DIRECTORY)
      if(NOT _dir IN_LIST CMAKE_CXX_IMPLICIT_LINK_DIRECTORIES AND NOT _dir IN_LIST _pdt_pc_dirs)
        list(APPEND _pdt_pc_dirs "${_dir}")
        string(APPEND _pdt_pc_libs " -L${_dir}")
      endif()
    endif()
  endforeach()
  foreach(_lib IN LISTS _pdt_pc_private)
    string(APPEND _pdt_pc_libs " -l${_lib}")
  endforeach()
endif()
if(PDT_SANITIZE)
  string(APPEND _pdt_pc_libs " -fsanitize=${PDT_SANITIZE}")  # as pdt::pdt's INTERFACE link option
endif()

configure_file(${PROJECT_SOURCE_DIR}/cmake/pdt.pc.in ${PROJECT_BINARY_DIR}/pdt.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/pdt.pc DESTINATION ${pdt_install_pkgconfigdir})
