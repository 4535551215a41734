#include "core/container/crc32.h"

#include <array>

namespace animspace::container {
namespace {

// Byte-at-a-time table: entry b is the CRC register after shifting in byte b from zero
// (Sarwate 1988). Computed by the compiler, so there is no first-use initialisation to race.
constexpr std::array<uint32_t, 256> make_table() {
  std::array<uint32_t, 256> table{};
  for (uint32_t byte = 0; byte < 256; ++byte) {
    uint32_t remainder = byte;
    for (int bit = 0; bit < 8; ++bit) {
      remainder = (remainder & 1U) != 0 ? (remainder >> 1) ^ 0xEDB88320U : remainder >> 1;
    }
    table[byte] = remainder;
  }
  return table;
}

constexpr std::array<uint32_t, 256> kTable = make_table();
static_assert(kTable[1] == 0x77073096U && kTable[255] == 0x2D02EF8DU,
              "CRC-32 table differs from the published IEEE 802.3 table");

}  // namespace

uint32_t crc32_update(uint32_t crc, std::span<const std::byte> bytes) {
  // The register holds the complement between calls so that leading zero bytes change the CRC.
  uint32_t state = ~crc;
  for (const std::byte b : bytes) {
    state = kTable[(state ^ std::to_integer<uint32_t>(b)) & 0xFFU] ^ (state >> 8);
  }
  return ~state;
}

uint32_t crc32_update(uint32_t crc, std::string_view bytes) {
  return crc32_update(crc, std::as_bytes(std::span<const char>(bytes.data(), bytes.size())));
}

}  // namespace animspace::container
