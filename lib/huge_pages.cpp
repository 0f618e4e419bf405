// SPDX-License-Identifier: MIT
#include "huge_pages.hpp"

#include <cstdlib>
#include <cstring>
#include <string>

#include "pdt/error.hpp"

namespace pdt::detail {

namespace {

bool read_setting() {
  const char* s = std::getenv("PDT_HUGE_PAGES");
  if (!s || !*s || std::strcmp(s, "0") == 0) return false;
  if (std::strcmp(s, "1") == 0) return true;
  throw Error(ErrorCode::invalid_argument,
              std::string("PDT_HUGE_PAGES='") + s + "' is not a valid value (expected 0 or 1)");
}

}  // namespace

bool huge_pages_advised() {
  static const bool advised = read_setting();  // a throw leaves it unset: read again next time
  return advised;
}

}  // namespace pdt::detail
