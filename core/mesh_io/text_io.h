// Shared pieces of the strict text parsers and writers in core/mesh_io (OBJ, TGF, DMAT, Tmat):
// a line/token reader whose errors read `source:line: expected …, got …`, and shortest
// round-trip number formatting.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "core/common/result.h"

namespace animspace::mesh_io {

// Walks a text buffer line by line and token by token. Tokens are separated by spaces, tabs and
// '\r' (so CRLF files read like LF files). `text` and `source` must outlive the reader.
class TextReader {
 public:
  TextReader(std::string_view text, std::string_view source) : text_(text), source_(source) {}

  // Moves to the next line; false at the end of the text.
  bool next_line();
  // 1-based number of the current line (0 before the first next_line()).
  int line_number() const { return line_number_; }
  // The next token of the current line; empty at the end of the line.
  std::string_view next_token();
  // The next token, moving on to later lines as needed (formats that are a stream of values);
  // empty at the end of the text.
  std::string_view next_token_any_line();
  // The bytes after the current line's '\n' (a binary payload after a text header).
  std::string_view rest_after_line() const { return text_.substr(next_line_start_); }

  // Parses the whole of `token` as a T (float, double or int). Floating-point values must be
  // finite; values too small for T round to zero, values too large are errors. `what` names the
  // expected value in the error: "source:line: expected <what>, got '<token>'".
  template <typename T>
  Result<T> parse(std::string_view token, std::string_view what) const;
  // parse<T>(next_token(), what).
  template <typename T>
  Result<T> read(std::string_view what) {
    return parse<T>(next_token(), what);
  }

  // "source:line: expected <expected>, got <got>" ('got' quoted; an empty 'got' reads
  // "end of line").
  Error error(std::string_view expected, std::string_view got) const;
  // "source:line: <message>" ("source: <message>" before the first line).
  Error error(std::string_view message) const;

 private:
  std::string_view text_;
  std::string_view source_;
  std::string_view line_;  // current line without its '\n'
  size_t next_line_start_ = 0;
  int line_number_ = 0;
};

// What a parser returns when an allocation fails: kResourceExhausted naming `source` (no
// exception leaves a public parse function).
Error out_of_memory_reading(std::string_view source);

// Appends the shortest decimal text that reads back to exactly `value` (std::to_chars), so text
// files written here round-trip float32 and float64 values bit for bit.
void append_number(std::string& out, float value);
void append_number(std::string& out, double value);
void append_number(std::string& out, int value);

// The extension of `path` in lower case, with its dot (".obj"), for case-insensitive dispatch.
std::string lowercase_extension(const std::filesystem::path& path);

}  // namespace animspace::mesh_io
