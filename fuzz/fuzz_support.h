// What every fuzz target shares: the input as bytes, and the invariant check.
//
// The parsers' contract is Result/Status (STYLE.md §5): a returned error is a pass, whatever the
// input. A crash is what libFuzzer records and saves, so a broken invariant aborts, and so does
// an exception (none may leave a public core function; nothing here catches one).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "core/common/result.h"

// Aborts naming the condition when it does not hold. Not assert(): it must hold in every build.
#define FUZZ_CHECK(condition)                                                              \
  do {                                                                                     \
    if (!(condition)) {                                                                    \
      std::fprintf(stderr, "%s:%d: invariant violated: %s\n", __FILE__, __LINE__, #condition); \
      std::abort();                                                                        \
    }                                                                                      \
  } while (false)

namespace animspace::fuzz {

inline std::string_view as_bytes(const uint8_t* data, size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// What every refusal from a parser of `source`'s bytes must look like: a message that names the
// source (the parsers document "`source` prefixes every error"), and never kInternal, which
// parse functions use for an exception they caught — a bug, not bad data.
inline void check_refusal(const Error& error, std::string_view source) {
  FUZZ_CHECK(error.code != ErrorCode::kInternal);
  FUZZ_CHECK(std::string_view(error.message).starts_with(source));
}

}  // namespace animspace::fuzz
