// SPDX-License-Identifier: MIT
#include "cli_text.hpp"

#include <cctype>
#include <charconv>
#include <cmath>

namespace pdt::support {

bool parse_real(std::string_view s, double& out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc{} && end == s.data() + s.size() && std::isfinite(out);
}

bool parse_count(std::string_view s, unsigned long long& out) {
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  if (!s.empty() && ec == std::errc{} && end == s.data() + s.size()) return true;
  double d = 0;
  if (!parse_real(s, d) || std::signbit(d) ||  // "-0" too: a count has no sign
       d > 9007199254740992.0 || d != std::floor(d)) return false;
  out = static_cast<unsigned long long>(d);
  return true;
}

std::string format_double(double v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc{} ? std::string(buf, end) : std::string("?");
}

bool ends_with_nocase(std::string_view s, std::string_view suffix) {
  if (suffix.size() > s.size()) return false;
  for (std::size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) !=
        std::tolower(static_cast<unsigned char>(suffix[i])))
      return false;
  return true;
}

}  // namespace pdt::support
