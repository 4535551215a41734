// Fixed-width fields of the binary formats (model container, miss log, PC2), read and written by
// copying memory: every format here is little-endian, and so is every host this builds for.
#pragma once

#include <bit>
#include <cassert>
#include <cstddef>
#include <cstring>
#include <string>
#include <string_view>

namespace animspace {

static_assert(std::endian::native == std::endian::little,
              "the binary formats are little-endian and are read and written by copying memory");

// The T at byte `at` of `bytes`; the caller has checked that it lies inside.
template <typename T>
T load_le(std::string_view bytes, size_t at) {
  assert(at <= bytes.size() && bytes.size() - at >= sizeof(T));
  T value{};
  std::memcpy(&value, bytes.data() + at, sizeof value);
  return value;
}

// Overwrites the T at byte `at` of `bytes`; the caller has checked that it lies inside.
template <typename T>
void store_le(std::string& bytes, size_t at, T value) {
  assert(at <= bytes.size() && bytes.size() - at >= sizeof(T));
  std::memcpy(bytes.data() + at, &value, sizeof value);
}

}  // namespace animspace
