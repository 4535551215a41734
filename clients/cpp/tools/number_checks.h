// Checks for numeric command-line options that say what is wanted ("must be > 0, got 0"), where
// CLI11's PositiveNumber and NonNegativeNumber print a range up to 1.8e308 in 300 digits — and
// "Value 0 not in range 0.000000 to …" for a positive one, which contradicts itself (issue #55).
#pragma once

#include <cmath>
#include <string>

#include <CLI/CLI.hpp>

namespace animspace::tools {

namespace detail {
inline CLI::Validator number_check(bool zero_allowed) {
  return CLI::Validator(
      [zero_allowed](std::string& input) -> std::string {
        double value = 0;
        std::size_t used = 0;
        try {
          value = std::stod(input, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != input.size() || std::isnan(value)) return "expected a number, got '" + input + "'";
        if (zero_allowed ? value < 0 : value <= 0) {
          return std::string(zero_allowed ? "must be >= 0" : "must be > 0") + ", got " + input;
        }
        return {};
      },
      zero_allowed ? "NUMBER >= 0" : "NUMBER > 0", zero_allowed ? "NONNEGATIVE" : "POSITIVE");
}
}  // namespace detail

// A value above zero; a value of zero or more.
inline const CLI::Validator kPositive = detail::number_check(false);
inline const CLI::Validator kNonNegative = detail::number_check(true);

}  // namespace animspace::tools
