# SPDX-License-Identifier: MIT
# vcpkg port for pdt. To build a local checkout instead of a release (no hash to
# update while developing):
#   PDT_SOURCE_DIR=/path/to/pdt vcpkg install pdt --overlay-ports=/path/to/pdt/ports
# Otherwise the sources come from GitHub.
if(DEFINED ENV{PDT_SOURCE_DIR})
  set(SOURCE_PATH "$ENV{PDT_SOURCE_DIR}")
  if(NOT EXISTS "${SOURCE_PATH}/CMakeLists.txt")
    message(FATAL_ERROR "PDT_SOURCE_DIR=${SOURCE_PATH} is not a pdt checkout (no CMakeLists.txt)")
  endif()
else()
  # Placeholder upstream: set REPO and the release's SHA512 when pdt is published.
  vcpkg_from_github(
    OUT_SOURCE_PATH SOURCE_PATH
    REPO pdt-project/pdt
    REF "v${VERSION}"
    SHA512 0
    HEAD_REF main
  )
endif()

if("mimalloc" IN_LIST FEATURES)
  set(PDT_ALLOCATOR mimalloc)
else()
  set(PDT_ALLOCATOR pool)
endif()

vcpkg_cmake_configure(
  SOURCE_PATH "${SOURCE_PATH}"
  OPTIONS
    -DPDT_ALLOCATOR=${PDT_ALLOCATOR}
    -DPDT_BUILD_TESTS=OFF
    -DPDT_BUILD_BENCH=OFF
    -DPDT_BUILD_TOOLS=OFF
    -DPDT_INSTALL_CMAKEDIR=share/pdt
)
vcpkg_cmake_install()
vcpkg_cmake_config_fixup(PACKAGE_NAME pdt CONFIG_PATH share/pdt)
vcpkg_fixup_pkgconfig()  # lib/pkgconfig/pdt.pc (and debug/): relocatable, checked with pkg-config

# Headers are the same in both configurations; vcpkg wants them once.
file(REMOVE_RECURSE "${CURRENT_PACKAGES_DIR}/debug/include" "${CURRENT_PACKAGES_DIR}/debug/share")

file(INSTALL "${CMAKE_CURRENT_LIST_DIR}/usage" DESTINATION "${CURRENT_PACKAGES_DIR}/share/${PORT}")
vcpkg_install_copyright(FILE_LIST "${SOURCE_PATH}/LICENSE")  # MIT, with what the binaries contain
