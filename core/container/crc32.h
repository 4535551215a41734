// CRC-32 as zlib, PNG, gzip and Ethernet compute it (IEEE 802.3 polynomial 0x04C11DB7, used
// bit-reflected as 0xEDB88320, initial value and final xor 0xFFFFFFFF). Check value:
// crc32("123456789") == 0xCBF43926.
//
// zlib's own (crc32_z): a byte-at-a-time table was most of the time a big model took to load.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace animspace::container {

// Continues a CRC over more bytes, like zlib's crc32(crc, buf, len): start with 0, pass the
// previous result back in. crc32_update(crc32_update(0, a), b) == crc32(a + b).
uint32_t crc32_update(uint32_t crc, std::span<const std::byte> bytes);
uint32_t crc32_update(uint32_t crc, std::string_view bytes);

// The CRC-32 of `bytes` in one call; 0 for no bytes.
inline uint32_t crc32(std::string_view bytes) { return crc32_update(0, bytes); }

}  // namespace animspace::container
