// Number formatting for error messages and text metadata: the shortest text that reads back as
// the same value ("3.5", not "3.500000"; std::to_string's fixed six decimals would turn 1e-7 into
// 0), so that a message quotes exactly what the caller sent.
#pragma once

#include <charconv>
#include <string>

namespace animspace {

inline std::string format_number(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

}  // namespace animspace
