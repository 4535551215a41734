// Tests of PNG encoding and decoding (core/render/png.h): exact round trips and refusals.
#include "core/render/png.h"

#include <cstdint>
#include <random>
#include <string>

#include <gtest/gtest.h>

namespace animspace::render {
namespace {

Image random_image(int width, int height, uint32_t seed) {
  std::mt19937 engine(seed);
  std::uniform_int_distribution<int> byte(0, 255);
  Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(4 * static_cast<size_t>(width) * static_cast<size_t>(height));
  for (uint8_t& value : image.rgba) value = static_cast<uint8_t>(byte(engine));
  return image;
}

TEST(PngTest, RoundTripIsExactAtEveryCompressionLevel) {
  const Image image = random_image(37, 23, 1);  // odd sizes: no row padding assumptions
  for (int level : {0, 1, 3, 6, 9}) {
    SCOPED_TRACE(level);
    Result<std::string> bytes = encode_png(image, level);
    ASSERT_TRUE(bytes.ok()) << bytes.error().message;
    EXPECT_EQ(bytes->substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    Result<Image> decoded = decode_png(*bytes, "round trip");
    ASSERT_TRUE(decoded.ok()) << decoded.error().message;
    EXPECT_EQ(decoded->width, image.width);
    EXPECT_EQ(decoded->height, image.height);
    EXPECT_EQ(decoded->rgba, image.rgba);
  }
}

TEST(PngTest, HigherCompressionLevelsCompressAFlatImageMore) {
  Image image;
  image.width = 256;
  image.height = 256;
  image.rgba.assign(4 * 256 * 256, 0);
  for (size_t i = 0; i < image.rgba.size(); ++i) image.rgba[i] = static_cast<uint8_t>((i / 4) % 7 * 30);
  Result<std::string> stored = encode_png(image, 0);
  Result<std::string> compressed = encode_png(image, 9);
  ASSERT_TRUE(stored.ok());
  ASSERT_TRUE(compressed.ok());
  EXPECT_GT(stored->size(), image.rgba.size());  // level 0 stores the deflate blocks uncompressed
  EXPECT_LT(compressed->size(), stored->size() / 10);
}

TEST(PngTest, EncodeRefusesEmptyAndMisSizedImages) {
  Image empty;
  Result<std::string> refused = encode_png(empty);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);

  Image short_buffer = random_image(4, 4, 2);
  short_buffer.rgba.pop_back();
  refused = encode_png(short_buffer);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("63"), std::string::npos) << refused.error().message;
}

TEST(PngTest, DecodeRefusesBytesThatAreNotAPng) {
  for (const std::string& bytes : {std::string(), std::string("not a png at all"), std::string(1000, '\x89')}) {
    Result<Image> decoded = decode_png(bytes, "upload.png");
    ASSERT_FALSE(decoded.ok());
    EXPECT_EQ(decoded.error().code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(decoded.error().message.rfind("upload.png: ", 0), 0u) << decoded.error().message;
  }
  // A real PNG cut short: the header reads, the pixels do not.
  Result<std::string> bytes = encode_png(random_image(64, 64, 3));
  ASSERT_TRUE(bytes.ok());
  Result<Image> truncated = decode_png(bytes->substr(0, bytes->size() / 2), "truncated.png");
  ASSERT_FALSE(truncated.ok());
  EXPECT_EQ(truncated.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace animspace::render
