// parse_number: a whole option value as a number, or false ("8x", "", " 8"
// and out-of-range values are errors), with std::from_chars (locale-free).
// Used where brick structure options are read.
//
// Thread-safety: a pure function.
#pragma once

#include <charconv>
#include <string>
#include <system_error>

namespace outcore {

template <class T>
bool parse_number(const std::string& text, T& out) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, out);
  return ec == std::errc() && ptr == end && !text.empty();
}

}  // namespace outcore
