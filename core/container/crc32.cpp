#include "core/container/crc32.h"

#include <algorithm>
#include <limits>

#include <zlib.h>

namespace animspace::container {

// zlib's crc32_z: the same CRC, several bytes a cycle where a byte-at-a-time table managed one
// (issue #53: the CRC of a 1.4 GB model file was most of the time a reload took).
uint32_t crc32_update(uint32_t crc, std::span<const std::byte> bytes) {
  uLong state = crc;
  const auto* data = reinterpret_cast<const Bytef*>(bytes.data());
  size_t left = bytes.size();
  while (left > 0) {  // z_size_t is size_t; chunks keep the cast honest on any platform
    const size_t chunk = std::min<size_t>(left, std::numeric_limits<uint32_t>::max());
    state = crc32_z(state, data, chunk);
    data += chunk;
    left -= chunk;
  }
  return static_cast<uint32_t>(state);
}

uint32_t crc32_update(uint32_t crc, std::string_view bytes) {
  return crc32_update(crc, std::as_bytes(std::span<const char>(bytes.data(), bytes.size())));
}

}  // namespace animspace::container
