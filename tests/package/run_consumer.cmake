# SPDX-License-Identifier: MIT
# ctest driver for the package.* tests (cmake -P): install a pdt build into a scratch
# prefix, then build and run tests/package/consumer against it twice, as a user would:
# with find_package(pdt CONFIG), and with `pkg-config --cflags --libs pdt`.
# Inputs (-D): PDT_SOURCE_DIR CONSUMER_SOURCE_DIR WORK_DIR PREFIX INIT_CACHE GENERATOR
#              CONFIG EXPECTED_VERSION, and
#   PDT_BUILD_DIR     the pdt build tree to install (the test's own build), unless SHARED
#   SHARED=ON         configure and build pdt itself first, as a shared library (only the
#                     library: no tests, benches or tool), in WORK_DIR/pdt-build, with
#                     PDT_ALLOCATOR and PDT_SANITIZE as given
#   PKG_CONFIG        pkg-config program; empty: the pkg-config consumer is skipped
#   PKG_CONFIG_EXTRA  more pkg-config search directories (':'-separated), for dependencies
#   CXX               the compiler for the pkg-config consumer
# INIT_CACHE puts PREFIX on CMAKE_PREFIX_PATH and carries the compiler and dependency packages.
foreach(var PDT_SOURCE_DIR CONSUMER_SOURCE_DIR WORK_DIR PREFIX INIT_CACHE GENERATOR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "run_consumer.cmake: -D${var}=... is required")
  endif()
endforeach()
if(NOT CONFIG)
  set(CONFIG Release)
endif()
if(SHARED)
  set(tag package.shared)
  set(PDT_BUILD_DIR ${WORK_DIR}/pdt-build)
elseif(NOT DEFINED PDT_BUILD_DIR)
  message(FATAL_ERROR "run_consumer.cmake: -DPDT_BUILD_DIR=... is required (or -DSHARED=ON)")
else()
  set(tag package.consumer)
endif()

set(prefix ${PREFIX})
set(build ${WORK_DIR}/consumer-build)
# Start clean: a stale prefix could hide a file the install no longer provides.
file(REMOVE_RECURSE ${prefix} ${build} ${WORK_DIR}/pkgconfig-consumer)

function(step what)
  string(TIMESTAMP t0 "%s")
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  string(TIMESTAMP t1 "%s")
  math(EXPR dt "${t1} - ${t0}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${tag}: ${what} failed (exit ${rc}):\n${ARGN}\n${out}")
  endif()
  message(STATUS "${tag}: ${what}: ok (${dt} s)")
  set(step_output "${out}" PARENT_SCOPE)
endfunction()
function(fail)
  string(CONCAT msg ${ARGN})
  message(FATAL_ERROR "${tag}: ${msg}")
endfunction()

if(SHARED)
  # A separate pdt build: only the library target, as cheap as a shared build can be.
  if(NOT EXISTS ${PDT_BUILD_DIR}/CMakeCache.txt)
    file(REMOVE_RECURSE ${PDT_BUILD_DIR})
  endif()
  step("configure pdt (BUILD_SHARED_LIBS=ON, allocator ${PDT_ALLOCATOR})"
       ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${PDT_SOURCE_DIR} -B ${PDT_BUILD_DIR} -G ${GENERATOR}
       -DCMAKE_BUILD_TYPE=${CONFIG} -DBUILD_SHARED_LIBS=ON -DPDT_BUILD_TESTS=OFF
       -DPDT_BUILD_BENCH=OFF -DPDT_BUILD_TOOLS=OFF -DPDT_INSTALL=ON
       "-DPDT_ALLOCATOR=${PDT_ALLOCATOR}" "-DPDT_SANITIZE=${PDT_SANITIZE}")
  if(DEFINED ENV{CMAKE_BUILD_PARALLEL_LEVEL})
    set(jobs $ENV{CMAKE_BUILD_PARALLEL_LEVEL})
  else()
    cmake_host_system_information(RESULT jobs QUERY NUMBER_OF_LOGICAL_CORES)
  endif()
  step("build pdt (shared)" ${CMAKE_COMMAND} --build ${PDT_BUILD_DIR} --config ${CONFIG} --parallel ${jobs})
endif()

step("install" ${CMAKE_COMMAND} --install ${PDT_BUILD_DIR} --prefix ${prefix} --config ${CONFIG})

# The install must be self-contained: no private headers, and no path back into
# the source or build tree in the exported targets.
file(GLOB_RECURSE config_files ${prefix}/*/pdtConfig.cmake)
if(NOT config_files)
  fail("no pdtConfig.cmake under ${prefix}")
endif()
if(NOT EXISTS ${prefix}/include/pdt/triangulation.hpp)
  fail("public headers missing under ${prefix}/include/pdt")
endif()
file(GLOB_RECURSE installed_headers RELATIVE ${prefix}/include ${prefix}/include/*)
file(GLOB_RECURSE public_headers RELATIVE ${PDT_SOURCE_DIR}/include ${PDT_SOURCE_DIR}/include/pdt/*.hpp)
if(NOT installed_headers STREQUAL public_headers)
  fail("installed headers differ from include/pdt/*.hpp:\n"
       "  installed: ${installed_headers}\n  public:    ${public_headers}")
endif()
file(GLOB_RECURSE target_files ${prefix}/*/pdtTargets*.cmake)
foreach(f ${target_files})
  file(READ ${f} text)
  foreach(tree ${PDT_SOURCE_DIR} ${PDT_BUILD_DIR})
    string(FIND "${text}" "${tree}" at)
    if(NOT at EQUAL -1)
      fail("${f} refers to ${tree}; the package is not relocatable")
    endif()
  endforeach()
  foreach(internal pdt_warnings pdt_internal)
    string(FIND "${text}" "${internal}" at)
    if(NOT at EQUAL -1)
      fail("${f} exports the private target ${internal}")
    endif()
  endforeach()
  # oneTBB is public (pdt's headers include it): linked, not only $<LINK_ONLY:...>.
  if(text MATCHES "INTERFACE_LINK_LIBRARIES \"([^\"]*)\"")
    string(REGEX REPLACE "\\$<LINK_ONLY:[^>]*>" "" public_links "${CMAKE_MATCH_1}")
    if(NOT public_links MATCHES "TBB::tbb")
      fail("${f}: TBB::tbb is not a public dependency of pdt::pdt:\n  ${CMAKE_MATCH_1}")
    endif()
  endif()
endforeach()

# The library kind is the one asked for, and pdtConfig.cmake knows it.
file(GLOB_RECURSE static_libs ${prefix}/*/libpdt.a)
file(GLOB_RECURSE shared_libs ${prefix}/*/libpdt.so*)
list(GET config_files 0 config_file)
file(READ ${config_file} config_text)
if(SHARED AND (NOT shared_libs OR static_libs))
  fail("expected a shared libpdt.so and no libpdt.a under ${prefix}: ${shared_libs} ${static_libs}")
endif()
if(static_libs AND shared_libs)
  fail("both libpdt.a and libpdt.so under ${prefix}")
elseif(static_libs AND NOT config_text MATCHES "set\\(pdt_STATIC ON\\)")
  fail("${config_file} does not say pdt_STATIC ON for a static libpdt.a")
elseif(shared_libs AND NOT config_text MATCHES "set\\(pdt_STATIC OFF\\)")
  fail("${config_file} does not say pdt_STATIC OFF for a shared libpdt.so")
endif()

step("configure consumer" ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${CONSUMER_SOURCE_DIR} -B ${build}
     -G ${GENERATOR} -DCMAKE_BUILD_TYPE=${CONFIG} -DEXPECTED_VERSION=${EXPECTED_VERSION})
step("build consumer" ${CMAKE_COMMAND} --build ${build} --config ${CONFIG})
# A consumer without a build type gets no warning from pdt's dependencies: CGAL's
# "performance notice" is about CGAL code compiled in the consumer, and pdt's is in libpdt.
file(REMOVE_RECURSE ${build}-untyped)
# A dependency missing at the consumer is reported with what to install.
execute_process(COMMAND ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${CONSUMER_SOURCE_DIR} -B ${build}-untyped
                -G ${GENERATOR} -DCMAKE_BUILD_TYPE=${CONFIG} -DEXPECTED_VERSION=${EXPECTED_VERSION}
                -DCMAKE_DISABLE_FIND_PACKAGE_TBB=ON
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
string(REGEX REPLACE "[ \t\r\n]+" " " out "${out}")  # CMake wraps the reason over lines
if(rc EQUAL 0 OR NOT out MATCHES "pdt needs TBB, which was not found: install oneTBB \\(Debian: libtbb-dev")
  fail("a consumer without oneTBB's package is not told what to install (exit ${rc}):\n${out}")
endif()
message(STATUS "${tag}: a missing dependency names its package: ok")
file(REMOVE_RECURSE ${build}-untyped)
step("configure consumer without a build type" ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${CONSUMER_SOURCE_DIR}
     -B ${build}-untyped -G ${GENERATOR} -DCMAKE_BUILD_TYPE= -DEXPECTED_VERSION=${EXPECTED_VERSION})
if(step_output MATCHES "CMake Warning|performance notice")
  fail("configuring a consumer without a build type warns:\n${step_output}")
endif()
file(REMOVE_RECURSE ${build}-untyped)

file(GLOB_RECURSE exe ${build}/pdt_consumer ${build}/*/pdt_consumer ${build}/pdt_consumer.exe ${build}/*/pdt_consumer.exe)
if(NOT exe)
  fail("pdt_consumer was not built in ${build}")
endif()
list(GET exe 0 exe)
step("run consumer" ${exe})

# --- pkg-config: the same consumer, compiled with `pkg-config --cflags --libs pdt` ---
if(NOT PKG_CONFIG)
  message(STATUS "${tag}: pkg-config consumer: SKIPPED (no pkg-config program found at configure time)")
  return()
endif()
file(GLOB_RECURSE pc_files ${prefix}/*/pdt.pc)
if(NOT pc_files)
  fail("no pdt.pc under ${prefix}")
endif()
list(GET pc_files 0 pc_file)
get_filename_component(pc_dir ${pc_file} DIRECTORY)
set(pc_path ${pc_dir})
if(PKG_CONFIG_EXTRA)
  string(APPEND pc_path ":${PKG_CONFIG_EXTRA}")
endif()
if(DEFINED ENV{PKG_CONFIG_PATH} AND NOT "$ENV{PKG_CONFIG_PATH}" STREQUAL "")
  string(APPEND pc_path ":$ENV{PKG_CONFIG_PATH}")
endif()
set(ENV{PKG_CONFIG_PATH} "${pc_path}")

step("pkg-config --modversion pdt" ${PKG_CONFIG} --modversion pdt)
string(STRIP "${step_output}" pc_version)
if(EXPECTED_VERSION AND NOT pc_version STREQUAL EXPECTED_VERSION)
  fail("pdt.pc says version ${pc_version}, expected ${EXPECTED_VERSION}")
endif()
step("pkg-config --print-requires pdt" ${PKG_CONFIG} --print-requires pdt)
if(NOT step_output MATCHES "(^|\n)tbb")
  fail("pdt.pc does not require tbb (pdt's headers include oneTBB):\n${step_output}")
endif()
# Relocatable: libdir lies in the prefix it was installed to, not in CMAKE_INSTALL_PREFIX.
step("pkg-config --variable=libdir pdt" ${PKG_CONFIG} --variable=libdir pdt)
string(STRIP "${step_output}" pc_libdir)
file(REAL_PATH "${pc_libdir}" pc_libdir_real)
file(REAL_PATH "${prefix}" prefix_real)
string(FIND "${pc_libdir_real}/" "${prefix_real}/" at)
if(NOT at EQUAL 0 OR NOT (EXISTS ${pc_libdir_real}/libpdt.a OR EXISTS ${pc_libdir_real}/libpdt.so))
  fail("pdt.pc's libdir ${pc_libdir} is not the installed ${prefix}/lib*; the .pc is not relocatable")
endif()
step("pkg-config --cflags --libs pdt" ${PKG_CONFIG} --cflags --libs pdt)
string(STRIP "${step_output}" pc_flags)
message(STATUS "${tag}: pkg-config --cflags --libs pdt: ${pc_flags}")
if(SHARED AND pc_flags MATCHES "-l(gmp|mpfr|z|mimalloc)( |$)")
  fail("pdt.pc links libpdt.so's private dependencies: ${pc_flags}")
endif()
separate_arguments(pc_args UNIX_COMMAND "${pc_flags}")
set(pc_exe ${WORK_DIR}/pkgconfig-consumer/pdt_consumer)
file(MAKE_DIRECTORY ${WORK_DIR}/pkgconfig-consumer)
step("build consumer with pkg-config"
     ${CXX} -std=c++20 ${CONSUMER_SOURCE_DIR}/main.cpp -o ${pc_exe} ${pc_args} "-Wl,-rpath,${pc_libdir}")
step("run consumer built with pkg-config" ${pc_exe})
