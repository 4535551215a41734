// Number formatting for error messages: the shortest text that reads back as the same value
// ("3.5", not "3.500000"), so that a message quotes exactly what the caller sent.
#pragma once

#include <charconv>
#include <string>

namespace animspace::render {

inline std::string format_number(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

}  // namespace animspace::render
