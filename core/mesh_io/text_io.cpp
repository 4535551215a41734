#include "core/mesh_io/text_io.h"

#include <cassert>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <system_error>
#include <type_traits>

namespace animspace::mesh_io {
namespace {

bool is_separator(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// from_chars reports both overflow and underflow as result_out_of_range; strtod tells them
// apart (it returns ±HUGE_VAL for overflow and a value below 1 in magnitude for underflow).
// Only reached on that rare error path, so the copy does not matter.
bool underflows(std::string_view digits, double& rounded) {
  const std::string copy(digits);
  rounded = std::strtod(copy.c_str(), nullptr);
  return std::abs(rounded) < 1.0;
}

template <typename T>
void append_with_to_chars(std::string& out, T value) {
  char buffer[32];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  assert(ec == std::errc{});
  out.append(buffer, end);
}

}  // namespace

bool TextReader::next_line() {
  if (next_line_start_ >= text_.size()) return false;
  const size_t newline = text_.find('\n', next_line_start_);
  const size_t end = newline == std::string_view::npos ? text_.size() : newline;
  line_ = text_.substr(next_line_start_, end - next_line_start_);
  next_line_start_ = newline == std::string_view::npos ? text_.size() : newline + 1;
  ++line_number_;
  return true;
}

std::string_view TextReader::next_token() {
  size_t begin = 0;
  while (begin < line_.size() && is_separator(line_[begin])) ++begin;
  size_t end = begin;
  while (end < line_.size() && !is_separator(line_[end])) ++end;
  const std::string_view token = line_.substr(begin, end - begin);
  line_.remove_prefix(end);
  return token;
}

std::string_view TextReader::next_token_any_line() {
  for (;;) {
    const std::string_view token = next_token();
    if (!token.empty()) return token;
    if (!next_line()) return {};
  }
}

template <typename T>
Result<T> TextReader::parse(std::string_view token, std::string_view what) const {
  // from_chars refuses the leading '+' that strtod and iostreams accept.
  std::string_view digits = token;
  if (digits.size() > 1 && digits[0] == '+' && digits[1] != '+' && digits[1] != '-') {
    digits.remove_prefix(1);
  }
  T value{};
  const char* end = digits.data() + digits.size();
  auto [stop, ec] = std::from_chars(digits.data(), end, value);
  if constexpr (std::is_floating_point_v<T>) {
    double rounded = 0;
    if (ec == std::errc::result_out_of_range && stop == end && underflows(digits, rounded)) {
      value = static_cast<T>(rounded);  // e.g. 1e-50 as float32: correctly rounds to ±0
      ec = std::errc{};
    }
    if (ec == std::errc{} && !std::isfinite(value)) ec = std::errc::invalid_argument;
  }
  if (digits.empty() || ec != std::errc{} || stop != end) return error(what, token);
  return value;
}

template Result<float> TextReader::parse<float>(std::string_view, std::string_view) const;
template Result<double> TextReader::parse<double>(std::string_view, std::string_view) const;
template Result<int> TextReader::parse<int>(std::string_view, std::string_view) const;

Error TextReader::error(std::string_view expected, std::string_view got) const {
  std::string message = "expected ";
  message += expected;
  message += ", got ";
  if (got.empty()) {
    message += "end of line";
  } else {
    // A binary file read as text can put megabytes on one "line"; quote only the start.
    constexpr size_t kMaxQuoted = 40;
    message += '\'';
    message += got.substr(0, kMaxQuoted);
    message += got.size() > kMaxQuoted ? "...'" : "'";
  }
  return error(message);
}

Error TextReader::error(std::string_view message) const {
  std::string text(source_);
  if (line_number_ > 0) {  // 0: the text has no line at all
    text += ':';
    text += std::to_string(line_number_);
  }
  text += ": ";
  text += message;
  return make_error(ErrorCode::kInvalidArgument, std::move(text));
}

std::string lowercase_extension(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension;
}

void append_number(std::string& out, float value) { append_with_to_chars(out, value); }
void append_number(std::string& out, double value) { append_with_to_chars(out, value); }
void append_number(std::string& out, int value) { append_with_to_chars(out, value); }

Error out_of_memory_reading(std::string_view source) {
  return make_error(ErrorCode::kResourceExhausted, std::string(source) + ": out of memory while reading");
}

}  // namespace animspace::mesh_io
