#include "core/mesh_io/pc2.h"

#include <bit>
#include <climits>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::TempDir;

// 2 points, 1 sample, startFrame 1, sampleRate 0.5, points (1, 2, -1) and (0.5, 0, 4): little
// endian bytes written out by hand from the IEEE 754 encodings.
const std::string kHandWritten = std::string(
    "POINTCACHE2\0"                     // magic
    "\x01\x00\x00\x00"                  // version 1
    "\x02\x00\x00\x00"                  // numPoints 2
    "\x00\x00\x80\x3f"                  // startFrame 1.0
    "\x00\x00\x00\x3f"                  // sampleRate 0.5
    "\x01\x00\x00\x00"                  // numSamples 1
    "\x00\x00\x80\x3f\x00\x00\x00\x40"  // 1.0 2.0
    "\x00\x00\x80\xbf\x00\x00\x00\x3f"  // -1.0 0.5
    "\x00\x00\x00\x00\x00\x00\x80\x40", // 0.0 4.0
    56);

// PC2 bytes from header fields and values (for corrupting one field at a time).
std::string pc2_bytes(int32_t version, int32_t num_points, float start_frame, float sample_rate, int32_t num_samples,
                      const std::vector<float>& values) {
  std::string bytes("POINTCACHE2\0", 12);
  const auto put = [&bytes](const auto& value) {
    char raw[sizeof(value)];
    std::memcpy(raw, &value, sizeof(value));
    bytes.append(raw, sizeof(value));
  };
  put(version);
  put(num_points);
  put(start_frame);
  put(sample_rate);
  put(num_samples);
  for (const float value : values) put(value);
  return bytes;
}

PointCache small_cache() {
  PointCache cache;
  cache.start_frame = 10;
  cache.sample_rate = 0.25f;
  cache.num_points = 7;
  cache.samples.resize(5, 21);
  for (Eigen::Index i = 0; i < cache.samples.size(); ++i) {
    cache.samples.data()[i] = std::ldexp(static_cast<float>(i) + 0.1f, static_cast<int>(i % 60) - 30) *
                              (i % 2 == 0 ? 1.0f : -1.0f);
  }
  return cache;
}

TEST(Pc2Parse, ReadsHandWrittenBytes) {
  const auto cache = parse_pc2(kHandWritten, "hand.pc2");
  ASSERT_TRUE(cache.ok()) << cache.error().message;
  EXPECT_EQ(cache->start_frame, 1.0f);
  EXPECT_EQ(cache->sample_rate, 0.5f);
  EXPECT_EQ(cache->num_points, 2);
  ASSERT_EQ(cache->num_frames(), 1);
  PointMatrix expected(2, 3);
  expected << 1, 2, -1, 0.5f, 0, 4;
  EXPECT_EQ(cache->frame(0), expected);
}

TEST(Pc2Serialize, WritesTheHandWrittenBytes) {
  PointCache cache;
  cache.start_frame = 1;
  cache.sample_rate = 0.5f;
  cache.num_points = 2;
  cache.samples.resize(1, 6);
  cache.samples << 1, 2, -1, 0.5f, 0, 4;
  EXPECT_EQ(serialize_pc2(cache), kHandWritten);
}

TEST(Pc2Parse, FrameIsOneRowReshapedToPoints) {
  const PointCache cache = small_cache();
  const PointMatrix frame = cache.frame(2);
  ASSERT_EQ(frame.rows(), 7);
  for (int p = 0; p < 7; ++p) {
    for (int axis = 0; axis < 3; ++axis) EXPECT_EQ(frame(p, axis), cache.samples(2, 3 * p + axis));
  }
}

TEST(Pc2File, RoundTripIsBitExact) {
  TempDir dir;
  const PointCache cache = small_cache();
  ASSERT_TRUE(write_pc2(dir / "cache.pc2", cache).ok());
  const auto read = read_pc2(dir / "cache.pc2");
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(read->start_frame, cache.start_frame);
  EXPECT_EQ(read->sample_rate, cache.sample_rate);
  EXPECT_EQ(read->num_points, cache.num_points);
  ASSERT_EQ(read->samples.rows(), cache.samples.rows());
  ASSERT_EQ(read->samples.cols(), cache.samples.cols());
  EXPECT_EQ(std::memcmp(read->samples.data(), cache.samples.data(), sizeof(float) * cache.samples.size()), 0);
}

TEST(Pc2File, MissingFileIsNotFound) {
  TempDir dir;
  const auto read = read_pc2(dir / "absent.pc2");
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.error().code, ErrorCode::kNotFound);
}

struct BadPc2 {
  const char* name;
  std::string bytes;
  ErrorCode code;
  const char* message;
};

class Pc2ParseErrors : public ::testing::TestWithParam<BadPc2> {};

TEST_P(Pc2ParseErrors, GiveCodeAndByteOffset) {
  const auto cache = parse_pc2(GetParam().bytes, "bad.pc2");
  ASSERT_FALSE(cache.ok());
  EXPECT_EQ(cache.error().code, GetParam().code) << cache.error().message;
  EXPECT_NE(cache.error().message.find(GetParam().message), std::string::npos) << cache.error().message;
}

const float kNan = std::numeric_limits<float>::quiet_NaN();
const std::vector<float> kTwoPointsOneFrame = {1, 2, 3, 4, 5, 6};

INSTANTIATE_TEST_SUITE_P(
    Table, Pc2ParseErrors,
    ::testing::Values(
        BadPc2{"ShortHeader", kHandWritten.substr(0, 10), ErrorCode::kDataLoss,
               "bad.pc2: byte 10: truncated header: expected 32 bytes, got 10"},
        BadPc2{"WrongMagic", "POINTCACHE3" + kHandWritten.substr(11), ErrorCode::kInvalidArgument,
               "bad.pc2: byte 0: expected the magic"},
        BadPc2{"Version2", pc2_bytes(2, 2, 0, 1, 1, kTwoPointsOneFrame), ErrorCode::kFailedPrecondition,
               "byte 12: unsupported version 2, expected 1"},
        BadPc2{"ZeroPoints", pc2_bytes(1, 0, 0, 1, 1, {}), ErrorCode::kInvalidArgument,
               "byte 16: expected numPoints > 0, got 0"},
        BadPc2{"NegativePoints", pc2_bytes(1, -5, 0, 1, 1, {}), ErrorCode::kInvalidArgument, "byte 16:"},
        BadPc2{"NanStartFrame", pc2_bytes(1, 2, kNan, 1, 1, kTwoPointsOneFrame), ErrorCode::kInvalidArgument,
               "byte 20: startFrame is not finite"},
        BadPc2{"ZeroSampleRate", pc2_bytes(1, 2, 0, 0, 1, kTwoPointsOneFrame), ErrorCode::kInvalidArgument,
               "byte 24: expected a finite sampleRate > 0"},
        BadPc2{"ZeroSamples", pc2_bytes(1, 2, 0, 1, 0, {}), ErrorCode::kInvalidArgument,
               "byte 28: expected numSamples > 0, got 0"},
        BadPc2{"NegativeSamples", pc2_bytes(1, 2, 0, 1, -1, {}), ErrorCode::kInvalidArgument, "byte 28:"},
        BadPc2{"TruncatedPayload", pc2_bytes(1, 2, 0, 1, 2, {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11}),
               ErrorCode::kDataLoss, "byte 76: truncated: the header's 2 samples × 2 points need 80 bytes, the data has 76"},
        BadPc2{"TrailingBytes", kHandWritten + "x", ErrorCode::kDataLoss, "trailing bytes"},
        BadPc2{"HugeCounts", pc2_bytes(1, 1000000000, 0, 1, 1000, {}), ErrorCode::kDataLoss,
               "need 12000000000032 bytes, the data has 32"},
        BadPc2{"CountsBeyond64Bits", pc2_bytes(1, INT_MAX, 0, 1, INT_MAX, {}), ErrorCode::kDataLoss,
               "need more than 2^64 bytes"},
        BadPc2{"NanValue", pc2_bytes(1, 2, 0, 1, 2, {1, 2, 3, 4, 5, 6, 7, kNan, 9, 10, 11, 12}),
               ErrorCode::kInvalidArgument, "bad.pc2: byte 60: non-finite value at frame 1, point 0, y"},
        BadPc2{"InfValue", pc2_bytes(1, 2, 0, 1, 1, {1, 2, 3, 4, 5, std::numeric_limits<float>::infinity()}),
               ErrorCode::kInvalidArgument, "byte 52: non-finite value at frame 0, point 1, z"}),
    [](const auto& test) { return std::string(test.param.name); });

TEST(Pc2File, WriteRefusesCachesThatWouldNotReadBack) {
  TempDir dir;
  PointCache wrong_columns = small_cache();
  wrong_columns.num_points = 6;
  PointCache no_points = small_cache();
  no_points.num_points = 0;
  no_points.samples.resize(5, 0);
  PointCache no_samples = small_cache();
  no_samples.samples.resize(0, 21);
  PointCache not_finite = small_cache();
  not_finite.samples(4, 20) = kNan;
  PointCache zero_rate = small_cache();
  zero_rate.sample_rate = 0;
  for (const PointCache* cache : {&wrong_columns, &no_points, &no_samples, &not_finite, &zero_rate}) {
    const Status written = write_pc2(dir / "out.pc2", *cache);
    ASSERT_FALSE(written.ok());
    EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(written.error().message.find("out.pc2"), std::string::npos) << written.error().message;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.pc2"));
}

}  // namespace
}  // namespace animspace::mesh_io
