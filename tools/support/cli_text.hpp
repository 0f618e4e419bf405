// SPDX-License-Identifier: MIT
#pragma once
// Tool support (not part of libpdt): reading numbers from the command line
// and writing doubles so that they read back exactly. std::from_chars and
// std::to_chars are locale independent and exact.
#include <string>
#include <string_view>

namespace pdt::support {

// The whole of s as a non-negative integer ("1000000"), or as a double that
// is integral and exact ("1e6"); false otherwise.
bool parse_count(std::string_view s, unsigned long long& out);
// The whole of s as a finite double; false otherwise.
bool parse_real(std::string_view s, double& out);
// Shortest text that reads back to exactly v.
std::string format_double(double v);
bool ends_with_nocase(std::string_view s, std::string_view suffix);

}  // namespace pdt::support
