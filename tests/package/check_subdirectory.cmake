# SPDX-License-Identifier: MIT
# ctest driver for package.subdirectory (cmake -P): configure tests/package/subdirectory,
# a project that includes pdt with add_subdirectory, twice, and check the compile
# commands it would run (nothing is built):
#  - with no CMAKE_BUILD_TYPE, libpdt's sources are compiled optimised (-O2 -DNDEBUG)
#    and the project's own target gets no flag from pdt;
#  - with CMAKE_BUILD_TYPE=Debug, pdt leaves the project's choice alone (no -O2);
#  - pdt's tests, benches and tool are not part of the project.
# Inputs (-D): PDT_SOURCE_DIR PROJECT_DIR WORK_DIR INIT_CACHE GENERATOR
foreach(var PDT_SOURCE_DIR PROJECT_DIR WORK_DIR INIT_CACHE GENERATOR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_subdirectory.cmake: -D${var}=... is required")
  endif()
endforeach()

function(configure_and_read build_type out_var)
  set(build ${WORK_DIR}/${build_type}-build)
  file(REMOVE_RECURSE ${build})
  execute_process(COMMAND ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${PROJECT_DIR} -B ${build}
                    -G ${GENERATOR} -DPDT_SOURCE_DIR=${PDT_SOURCE_DIR}
                    -DCMAKE_EXPORT_COMPILE_COMMANDS=ON -DCMAKE_BUILD_TYPE=${build_type}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "package.subdirectory: configure (build type '${build_type}') failed:\n${out}")
  endif()
  file(READ ${build}/compile_commands.json json)
  set(${out_var} "${json}" PARENT_SCOPE)
endfunction()

# The command for one source file, by the end of its path.
function(command_for json suffix out_var)
  string(JSON n LENGTH "${json}")
  math(EXPR last "${n} - 1")
  foreach(i RANGE ${last})
    string(JSON file GET "${json}" ${i} file)
    if(file MATCHES "${suffix}$")
      string(JSON cmd GET "${json}" ${i} command)
      set(${out_var} "${cmd}" PARENT_SCOPE)
      return()
    endif()
  endforeach()
  message(FATAL_ERROR "package.subdirectory: no compile command for ${suffix}")
endfunction()

configure_and_read("" untyped)
command_for("${untyped}" "/lib/triangulation.cpp" lib_cmd)
command_for("${untyped}" "/lib/engine.cpp" lib_cmd2)
command_for("${untyped}" "/package/consumer/main.cpp" app_cmd)
foreach(cmd IN ITEMS "${lib_cmd}" "${lib_cmd2}")
  if(NOT cmd MATCHES " -O2( |$)" OR NOT cmd MATCHES " -DNDEBUG( |$)")
    message(FATAL_ERROR "package.subdirectory: with no build type, libpdt is not compiled optimised:\n${cmd}")
  endif()
endforeach()
if(app_cmd MATCHES " -O2( |$)" OR app_cmd MATCHES "NDEBUG")
  message(FATAL_ERROR "package.subdirectory: pdt changed the including project's own flags:\n${app_cmd}")
endif()
if(untyped MATCHES "/tests/test_|/bench/bench_|/tools/cli.cpp")
  message(FATAL_ERROR "package.subdirectory: pdt's tests, benches or tool are built in a project that includes it")
endif()

configure_and_read(Debug debug)
command_for("${debug}" "/lib/triangulation.cpp" lib_cmd)
if(lib_cmd MATCHES " -O2( |$)" OR lib_cmd MATCHES "NDEBUG")
  message(FATAL_ERROR "package.subdirectory: with CMAKE_BUILD_TYPE=Debug, pdt overrode the project's choice:\n${lib_cmd}")
endif()
message(STATUS "package.subdirectory: ok")
