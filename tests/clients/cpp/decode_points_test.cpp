// The C++ client's decode_points against core's codec (core/common/point_codec.h, tested on its
// own against hand-worked patterns): the client carries its own binary16 decoder, because the
// client library depends only on the generated stubs.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "clients/cpp/results.h"
#include "core/common/point_codec.h"

namespace animspace {
namespace {

TEST(ClientDecodePoints, Float16AgreesWithTheCoreCodecOnEveryPattern) {
  std::vector<uint16_t> all(65536);
  for (uint32_t h = 0; h < all.size(); ++h) all[h] = static_cast<uint16_t>(h);
  v1::PointArray array;
  array.set_point_count(65536 / 4);
  array.set_channel_count(4);
  array.set_encoding(v1::POINT_ENCODING_FLOAT16);
  array.set_data(all.data(), all.size() * 2);
  array.set_max_error(0.125f);
  const Points points = decode_points(array);
  EXPECT_EQ(points.max_error, 0.125f);
  ASSERT_EQ(points.values.size(), all.size());
  for (size_t i = 0; i < all.size(); ++i) {
    const float core = point_codec::half_to_float(all[i]);
    ASSERT_EQ(std::memcmp(&points.values[i], &core, sizeof core), 0) << std::hex << i;
  }
}

TEST(ClientDecodePoints, Fixed16AgreesWithTheCoreCodec) {
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(100.0f, 3.0f);
  std::vector<float> values(3 * 1000);
  for (float& v : values) v = noise(rng);
  v1::PointArray array;
  array.set_point_count(1000);
  array.set_channel_count(3);
  array.set_encoding(v1::POINT_ENCODING_FIXED16);
  std::string bytes(2 * values.size(), '\0');
  std::vector<float> scale(3), offset(3);
  auto max_error = point_codec::encode_fixed16(values, 3, bytes, scale, offset);
  ASSERT_TRUE(max_error.ok());
  array.set_data(bytes);
  for (int c = 0; c < 3; ++c) {
    array.add_scale(scale[static_cast<size_t>(c)]);
    array.add_offset(offset[static_cast<size_t>(c)]);
  }
  array.set_max_error(*max_error);
  const Points points = decode_points(array);
  std::vector<float> core(values.size());
  point_codec::decode_fixed16(bytes, scale, offset, core);
  EXPECT_EQ(points.values, core);
  for (size_t i = 0; i < values.size(); ++i) ASSERT_LE(std::abs(points.values[i] - values[i]), points.max_error);
}

TEST(ClientDecodePoints, MalformedArraysThrow) {
  v1::PointArray array;
  array.set_point_count(2);
  array.set_channel_count(3);
  array.set_encoding(v1::POINT_ENCODING_FLOAT16);
  array.set_data(std::string(24, '\0'));  // float32's length
  EXPECT_THROW(decode_points(array), std::runtime_error);
  array.set_data(std::string(12, '\0'));
  EXPECT_NO_THROW(decode_points(array));
  array.set_encoding(v1::POINT_ENCODING_FIXED16);
  array.add_scale(1.0f);
  EXPECT_THROW(decode_points(array), std::runtime_error);  // one scale for three channels
  array.set_encoding(static_cast<v1::PointEncoding>(11));
  EXPECT_THROW(decode_points(array), std::runtime_error);
}

}  // namespace
}  // namespace animspace
