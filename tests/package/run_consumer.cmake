# ctest driver for package.consumer (cmake -P): install the pdt build tree into a
# scratch prefix, then configure, build and run tests/package/consumer against it.
# Inputs (-D): PDT_BUILD_DIR PDT_SOURCE_DIR CONSUMER_SOURCE_DIR WORK_DIR PREFIX INIT_CACHE
#              GENERATOR CONFIG EXPECTED_VERSION. INIT_CACHE puts PREFIX on CMAKE_PREFIX_PATH.
foreach(var PDT_BUILD_DIR PDT_SOURCE_DIR CONSUMER_SOURCE_DIR WORK_DIR PREFIX INIT_CACHE GENERATOR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "run_consumer.cmake: -D${var}=... is required")
  endif()
endforeach()
if(NOT CONFIG)
  set(CONFIG Release)
endif()

set(prefix ${PREFIX})
set(build ${WORK_DIR}/consumer-build)
# Start clean: a stale prefix could hide a file the install no longer provides.
file(REMOVE_RECURSE ${prefix} ${build})

function(step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "package.consumer: ${what} failed (exit ${rc}):\n${ARGN}\n${out}")
  endif()
  message(STATUS "package.consumer: ${what}: ok")
endfunction()

step("install" ${CMAKE_COMMAND} --install ${PDT_BUILD_DIR} --prefix ${prefix} --config ${CONFIG})

# The install must be self-contained: no private headers, and no path back into
# the source or build tree in the exported targets.
file(GLOB_RECURSE config_files ${prefix}/*/pdtConfig.cmake)
if(NOT config_files)
  message(FATAL_ERROR "package.consumer: no pdtConfig.cmake under ${prefix}")
endif()
if(NOT EXISTS ${prefix}/include/pdt/triangulation.hpp)
  message(FATAL_ERROR "package.consumer: public headers missing under ${prefix}/include/pdt")
endif()
file(GLOB_RECURSE installed_headers RELATIVE ${prefix}/include ${prefix}/include/*)
file(GLOB_RECURSE public_headers RELATIVE ${PDT_SOURCE_DIR}/include ${PDT_SOURCE_DIR}/include/pdt/*.hpp)
if(NOT installed_headers STREQUAL public_headers)
  message(FATAL_ERROR "package.consumer: installed headers differ from include/pdt/*.hpp:\n"
                      "  installed: ${installed_headers}\n  public:    ${public_headers}")
endif()
file(GLOB_RECURSE target_files ${prefix}/*/pdtTargets*.cmake)
foreach(f ${target_files})
  file(READ ${f} text)
  foreach(tree ${PDT_SOURCE_DIR} ${PDT_BUILD_DIR})
    string(FIND "${text}" "${tree}" at)
    if(NOT at EQUAL -1)
      message(FATAL_ERROR "package.consumer: ${f} refers to ${tree}; the package is not relocatable")
    endif()
  endforeach()
  foreach(internal pdt_warnings pdt_internal)
    string(FIND "${text}" "${internal}" at)
    if(NOT at EQUAL -1)
      message(FATAL_ERROR "package.consumer: ${f} exports the private target ${internal}")
    endif()
  endforeach()
endforeach()

step("configure consumer" ${CMAKE_COMMAND} -C ${INIT_CACHE} -S ${CONSUMER_SOURCE_DIR} -B ${build}
     -G ${GENERATOR} -DCMAKE_BUILD_TYPE=${CONFIG} -DEXPECTED_VERSION=${EXPECTED_VERSION})
step("build consumer" ${CMAKE_COMMAND} --build ${build} --config ${CONFIG})

file(GLOB_RECURSE exe ${build}/pdt_consumer ${build}/*/pdt_consumer ${build}/pdt_consumer.exe ${build}/*/pdt_consumer.exe)
if(NOT exe)
  message(FATAL_ERROR "package.consumer: pdt_consumer was not built in ${build}")
endif()
list(GET exe 0 exe)
step("run consumer" ${exe})
