#include "core/container/crc32.h"

#include <array>
#include <cstddef>
#include <string>
#include <string_view>

#include <gtest/gtest.h>

namespace animspace::container {
namespace {

// Published check values (the CRC catalogue's CRC-32/ISO-HDLC entry; zlib's crc32 and Python's
// zlib.crc32 give the same), not values computed by this code.
struct KnownValue {
  std::string_view input;
  uint32_t crc;
};
constexpr std::array<KnownValue, 4> kKnownValues = {{
    {"", 0x00000000U},
    {"a", 0xE8B7BE43U},
    {"123456789", 0xCBF43926U},
    {"The quick brown fox jumps over the lazy dog", 0x414FA339U},
}};

TEST(Crc32Test, MatchesPublishedCheckValues) {
  for (const KnownValue& known : kKnownValues) {
    EXPECT_EQ(crc32(known.input), known.crc) << "input \"" << known.input << "\"";
  }
}

TEST(Crc32Test, IncrementalEqualsOneShotAtEverySplit) {
  const std::string_view text = "The quick brown fox jumps over the lazy dog";
  for (size_t split = 0; split <= text.size(); ++split) {
    const uint32_t first = crc32_update(0, text.substr(0, split));
    EXPECT_EQ(crc32_update(first, text.substr(split)), 0x414FA339U) << "split at " << split;
  }
}

TEST(Crc32Test, ByteSpanOverloadAgreesWithStringView) {
  const std::string_view text = "123456789";
  const auto bytes = std::as_bytes(std::span<const char>(text.data(), text.size()));
  EXPECT_EQ(crc32_update(0, bytes), 0xCBF43926U);
  EXPECT_EQ(crc32_update(crc32_update(0, bytes.first(4)), bytes.subspan(4)), 0xCBF43926U);
}

TEST(Crc32Test, EmptyUpdateKeepsTheCrc) {
  EXPECT_EQ(crc32_update(0xCBF43926U, std::string_view()), 0xCBF43926U);
}

TEST(Crc32Test, DetectsEverySingleBitFlipAndLeadingZeros) {
  std::string data(64, '\0');
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<char>(i * 37 + 11);
  const uint32_t reference = crc32(data);
  for (size_t i = 0; i < data.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::string flipped = data;
      flipped[i] = static_cast<char>(flipped[i] ^ (1 << bit));
      EXPECT_NE(crc32(flipped), reference) << "byte " << i << " bit " << bit;
    }
  }
  // The complemented register makes leading zero bytes count.
  EXPECT_NE(crc32(std::string(1, '\0') + data), reference);
  EXPECT_NE(crc32(std::string(1, '\0')), 0U);
}

}  // namespace
}  // namespace animspace::container
