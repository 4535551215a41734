#include "core/common/point_codec.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::point_codec {
namespace {

// The conversions under test; F16C only where this machine has it.
std::vector<HalfConversion> conversions() {
  std::vector<HalfConversion> out = {HalfConversion::kScalar};
  if (f16c_available()) out.push_back(HalfConversion::kF16c);
  return out;
}

const char* name(HalfConversion c) { return c == HalfConversion::kF16c ? "F16C" : "scalar"; }

// binary16 as the standard defines it, in double: (−1)^s · 2^(e−15) · (1 + f/1024) for normal e,
// (−1)^s · 2^-14 · f/1024 for e = 0. Independent of the code under test.
double half_value(uint16_t h) {
  const int sign = (h & 0x8000) != 0 ? -1 : 1;
  const int e = (h >> 10) & 0x1F;
  const int f = h & 0x3FF;
  if (e == 0) return sign * std::ldexp(f, -24);
  return sign * std::ldexp(1024 + f, e - 25);
}

// The nearest binary16 to a finite v with |v| ≤ 65504 by search over all finite non-negative
// halves (ascending as integers), ties to the even pattern.
uint16_t nearest_half(float v) {
  const double a = std::fabs(static_cast<double>(v));
  uint16_t lo = 0;
  uint16_t hi = 0x7BFF;
  while (hi - lo > 1) {
    const auto mid = static_cast<uint16_t>((lo + hi) / 2);
    (half_value(mid) <= a ? lo : hi) = mid;
  }
  uint16_t best;
  if (half_value(hi) <= a) {
    best = hi;
  } else {
    const double below = a - half_value(lo);
    const double above = half_value(hi) - a;
    best = below < above ? lo : above < below ? hi : ((lo & 1) == 0 ? lo : hi);
  }
  return static_cast<uint16_t>(best | (std::signbit(v) ? 0x8000 : 0));
}

std::vector<uint16_t> halves_of(const std::vector<char>& bytes) {
  std::vector<uint16_t> out(bytes.size() / 2);
  if (!bytes.empty()) std::memcpy(out.data(), bytes.data(), bytes.size());  // an empty vector's data() may be null
  return out;
}

TEST(Float16, HandWorkedBitPatterns) {
  struct Case {
    float value;
    uint16_t bits;
  };
  const Case cases[] = {
      {1.0f, 0x3C00},
      {-2.0f, 0xC000},
      {0.5f, 0x3800},
      {65504.0f, 0x7BFF},                 // the largest half
      {0x1p-24f, 0x0001},                 // the smallest subnormal
      {0x1p-14f, 0x0400},                 // the smallest normal
      {1023 * 0x1p-24f, 0x03FF},          // the largest subnormal
      {0.0f, 0x0000},
      {-0.0f, 0x8000},
      // Half-way cases, ties to even: 1 + 2^-11 lies between 0x3C00 (even) and 0x3C01.
      {1.0f + 0x1p-11f, 0x3C00},
      {1.0f + 3 * 0x1p-11f, 0x3C02},      // between 0x3C01 and 0x3C02 (even)
      {1.0f + 0x1p-11f + 0x1p-23f, 0x3C01},  // just above the tie
      {0x1p-25f, 0x0000},                 // between 0 (even) and 0x0001
      {3 * 0x1p-25f, 0x0002},             // between 0x0001 and 0x0002 (even)
      {0x1p-25f + 0x1p-40f, 0x0001},
      {1023.5f * 0x1p-24f, 0x0400},       // a subnormal tie rounding up into the normals
      {65519.0f, 0x7BFF},                 // below the tie at 65520
      {2049.0f, 0x6800},                  // 2^11 + 1: tie between 2048 (even) and 2050
      {2051.0f, 0x6802},                  // tie between 2050 and 2052 (even)
  };
  for (const Case& c : cases) {
    EXPECT_EQ(float_to_half(c.value), c.bits) << c.value;
    EXPECT_EQ(nearest_half(c.value), c.bits) << "the test's own reference, " << c.value;
  }
  EXPECT_EQ(float_to_half(65520.0f), 0x7C00) << "the tie at 65520 goes to the even 2^16: Inf";
  EXPECT_EQ(float_to_half(-std::numeric_limits<float>::infinity()), 0xFC00);
  EXPECT_EQ(float_to_half(std::numeric_limits<float>::quiet_NaN()) & 0x7C00, 0x7C00);
  EXPECT_NE(float_to_half(std::numeric_limits<float>::quiet_NaN()) & 0x03FF, 0);
  EXPECT_EQ(half_to_float(0x3C00), 1.0f);
  EXPECT_EQ(half_to_float(0x0001), 0x1p-24f);
  EXPECT_EQ(half_to_float(0x7BFF), 65504.0f);
  EXPECT_EQ(half_to_float(0x7C00), std::numeric_limits<float>::infinity());
  EXPECT_TRUE(std::isnan(half_to_float(0x7E00)));
}

TEST(Float16, EveryHalfDecodesToTheStandardValueAndBack) {
  for (uint32_t h = 0; h <= 0xFFFF; ++h) {
    const auto bits = static_cast<uint16_t>(h);
    if ((bits & 0x7C00) == 0x7C00) continue;  // Inf and NaN: above
    const float f = half_to_float(bits);
    ASSERT_EQ(static_cast<double>(f), half_value(bits)) << std::hex << h;
    ASSERT_EQ(float_to_half(f), bits) << std::hex << h;
  }
}

TEST(Float16, RoundsRandomFloatsToTheNearestHalf) {
  std::mt19937 rng(25);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  std::uniform_int_distribution<int> exponent(-30, 15);
  for (int i = 0; i < 200000; ++i) {
    const float v = std::ldexp(unit(rng), exponent(rng));
    ASSERT_EQ(float_to_half(v), nearest_half(v)) << v;
  }
  // Every float of a few binades around the subnormal boundary, and around 1.
  for (float start : {0x1p-26f, 0x1p-15f, 0.999f}) {
    float v = start;
    for (int i = 0; i < 100000; ++i, v = std::nextafter(v, 2.0f)) {
      ASSERT_EQ(float_to_half(v), nearest_half(v)) << v;
    }
  }
}

// Random and edge values: both paths give the same bits, and the scalar bits the reference's.
std::vector<float> random_and_edge_values(size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  std::uniform_int_distribution<int> exponent(-30, 15);
  std::vector<float> values = {0.0f,       -0.0f,       1.0f,          65504.0f,       -65504.0f,     65503.99f,
                               0x1p-24f,   -0x1p-25f,   3 * 0x1p-25f,  1023.5f * 0x1p-24f, 1e-40f,  -1e-45f,
                               1.0f + 0x1p-11f, 2049.0f, 0x1p-14f};
  while (values.size() < count) values.push_back(std::ldexp(unit(rng), exponent(rng)));
  values.resize(count);
  return values;
}

TEST(Float16, ScalarAndF16cPathsAgree) {
  if (!f16c_available()) GTEST_SKIP() << "no F16C on this CPU: only the scalar path runs";
  // Lengths around the 8-value block, so that the padded tail is exercised.
  for (size_t count : {0u, 1u, 7u, 8u, 9u, 15u, 16u, 17u, 1000u, 4099u}) {
    const std::vector<float> values = random_and_edge_values(count, static_cast<uint32_t>(count));
    std::vector<char> scalar(2 * count), f16c(2 * count);
    const auto a = encode_float16(values, 3, scalar, HalfConversion::kScalar);
    const auto b = encode_float16(values, 3, f16c, HalfConversion::kF16c);
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_EQ(halves_of(scalar), halves_of(f16c)) << count;
    EXPECT_EQ(*a, *b) << count;
  }
  // Decoding: every pattern, Inf and NaN included, bit for bit.
  std::vector<char> all(2 * 65536);
  for (uint32_t h = 0; h <= 0xFFFF; ++h) {
    const auto bits = static_cast<uint16_t>(h);
    std::memcpy(all.data() + 2 * h, &bits, 2);
  }
  std::vector<float> scalar(65536), f16c(65536);
  decode_float16(all, scalar, HalfConversion::kScalar);
  decode_float16(all, f16c, HalfConversion::kF16c);
  for (size_t i = 0; i < scalar.size(); ++i) {
    uint32_t x, y;
    std::memcpy(&x, &scalar[i], 4);
    std::memcpy(&y, &f16c[i], 4);
    ASSERT_EQ(x, y) << std::hex << i;
  }
  // A tail shorter than a block.
  std::vector<float> five(5);
  decode_float16(std::span<const char>(all).subspan(2 * 0x3C00, 10), five, HalfConversion::kF16c);
  EXPECT_EQ(five[0], 1.0f);
}

TEST(Float16, ReportsTheExactLargestError) {
  for (HalfConversion conversion : conversions()) {
    for (size_t count : {1u, 13u, 3000u}) {
      const std::vector<float> values = random_and_edge_values(count, 7 + static_cast<uint32_t>(count));
      std::vector<char> bytes(2 * count);
      const auto max_error = encode_float16(values, 3, bytes, conversion);
      ASSERT_TRUE(max_error.ok()) << name(conversion);
      const std::vector<uint16_t> halves = halves_of(bytes);
      double worst = 0.0;
      for (size_t i = 0; i < count; ++i) {
        ASSERT_EQ(halves[i], nearest_half(values[i])) << name(conversion) << " " << values[i];
        const double error = std::fabs(half_value(halves[i]) - static_cast<double>(values[i]));
        // The stated bound: 2^-11 relative in the normals, 2^-25 absolute below.
        EXPECT_LE(error, std::max(std::ldexp(std::fabs(static_cast<double>(values[i])), -11), std::ldexp(1.0, -25)));
        worst = std::max(worst, error);
      }
      EXPECT_EQ(static_cast<double>(*max_error), worst) << name(conversion) << " " << count;
      std::vector<float> decoded(count);
      decode_float16(bytes, decoded, conversion);
      for (size_t i = 0; i < count; ++i) ASSERT_EQ(static_cast<double>(decoded[i]), half_value(halves[i]));
    }
  }
}

TEST(Float16, RefusesWhatItCannotCarryNamingTheValue) {
  for (HalfConversion conversion : conversions()) {
    std::vector<float> values(20, 1.0f);
    std::vector<char> bytes(40);
    values[13] = std::nextafter(65504.0f, 1e9f);
    auto r = encode_float16(values, 3, bytes, conversion);
    ASSERT_FALSE(r.ok()) << name(conversion);
    EXPECT_EQ(r.error().code, ErrorCode::kOutOfRange);
    EXPECT_NE(r.error().message.find("point 4, channel 1"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("65504"), std::string::npos) << r.error().message;
    values[13] = -1e6f;
    EXPECT_FALSE(encode_float16(values, 3, bytes, conversion).ok());
    values[13] = 1.0f;
    values[19] = std::numeric_limits<float>::quiet_NaN();  // in the padded tail
    r = encode_float16(values, 3, bytes, conversion);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("point 6, channel 1 is NaN"), std::string::npos) << r.error().message;
    values[19] = std::numeric_limits<float>::infinity();
    EXPECT_FALSE(encode_float16(values, 3, bytes, conversion).ok());
    values[19] = -65504.0f;
    EXPECT_TRUE(encode_float16(values, 3, bytes, conversion).ok()) << "±65504 itself is a half";
  }
}

// ---- fixed16 ----------------------------------------------------------------------------------

struct Fixed16 {
  std::vector<char> bytes;
  std::vector<float> scale, offset;
  float max_error = 0.0f;
};

Fixed16 encode(const std::vector<float>& values, size_t channels) {
  Fixed16 out;
  out.bytes.resize(2 * values.size());
  out.scale.resize(channels);
  out.offset.resize(channels);
  auto r = encode_fixed16(values, channels, out.bytes, out.scale, out.offset);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  if (r.ok()) out.max_error = *r;
  return out;
}

// Checks one encoding against the header's statement, by brute force over every value.
void expect_within_stated_bound(const std::vector<float>& values, size_t channels, const Fixed16& f) {
  const size_t n = values.size() / channels;
  std::vector<float> decoded(values.size());
  decode_fixed16(f.bytes, f.scale, f.offset, decoded);
  const std::vector<uint16_t> q = halves_of(f.bytes);
  double worst = 0.0;
  for (size_t c = 0; c < channels; ++c) {
    float lo = values[c], hi = values[c];
    for (size_t p = 0; p < n; ++p) {
      lo = std::min(lo, values[p * channels + c]);
      hi = std::max(hi, values[p * channels + c]);
    }
    const double range = static_cast<double>(hi) - static_cast<double>(lo);
    EXPECT_EQ(f.offset[c], lo);
    if (range == 0.0) {
      EXPECT_EQ(f.scale[c], 0.0f);
    } else {
      // (max − min)/65535 rounded up to float32: covers the range, and is its nearest float above.
      EXPECT_GE(static_cast<double>(f.scale[c]) * 65535.0, range);
      EXPECT_LT(static_cast<double>(std::nextafter(f.scale[c], 0.0f)) * 65535.0, range);
    }
    const double bound = static_cast<double>(f.scale[c]) / 2 +
                         std::ldexp(range + std::max(std::fabs(static_cast<double>(lo)), std::fabs(static_cast<double>(hi))), -23);
    for (size_t p = 0; p < n; ++p) {
      const size_t i = p * channels + c;
      // The decoder's formula, written out: two float32 roundings.
      const float step = f.scale[c] * static_cast<float>(q[i]);
      const float expected = f.offset[c] + step;
      ASSERT_EQ(decoded[i], expected);
      const double error = std::fabs(static_cast<double>(decoded[i]) - static_cast<double>(values[i]));
      ASSERT_LE(error, bound) << "point " << p << " channel " << c;
      worst = std::max(worst, error);
    }
  }
  // The reported maximum: the smallest float32 not below the brute-force maximum (exact in double
  // for these magnitudes).
  EXPECT_GE(static_cast<double>(f.max_error), worst);
  EXPECT_LT(static_cast<double>(std::nextafter(f.max_error, 0.0f)), worst == 0.0 ? 1e-300 : worst);
}

TEST(Fixed16, ErrorWithinTheStatedBoundOnRandomArrays) {
  std::mt19937 rng(2025);
  // Scale robustness (STYLE §6): small and large magnitudes, offsets far from the origin.
  for (double magnitude : {1e-4, 1.0, 1e4}) {
    for (double centre : {0.0, 1e3, -7.5}) {
      for (size_t channels : {1u, 3u, 4u}) {
        std::normal_distribution<double> noise(centre * magnitude, magnitude);
        const size_t n = 1 + rng() % 5000;
        std::vector<float> values(n * channels);
        for (float& v : values) v = static_cast<float>(noise(rng));
        const Fixed16 f = encode(values, channels);
        expect_within_stated_bound(values, channels, f);
      }
    }
  }
}

TEST(Fixed16, ConstantChannelsAndTinyRangesAreExact) {
  // Channel 1 constant: scale 0, every q 0, decoded exactly.
  const std::vector<float> values = {1.0f, 5.0f, -2.0f, 3.0f, 5.0f, 7.0f, 2.0f, 5.0f, 0.25f};
  const Fixed16 f = encode(values, 3);
  EXPECT_EQ(f.scale[1], 0.0f);
  expect_within_stated_bound(values, 3, f);
  // A range among the float32 subnormals: the step must not round to 0.
  const std::vector<float> tiny = {1e-45f, 4e-45f, 0.0f};
  const Fixed16 g = encode(tiny, 1);
  EXPECT_GT(g.scale[0], 0.0f);
  EXPECT_EQ(g.max_error, 0.0f) << "every subnormal in a range of 3 steps of 2^-149 is a multiple of the step";
  expect_within_stated_bound(tiny, 1, g);
  // Large values of both signs: the range (2e38) is near FLT_MAX, the step is not.
  const std::vector<float> large = {-1e38f, 1e38f, 1e30f};
  expect_within_stated_bound(large, 1, encode(large, 1));
  // A range beyond FLT_MAX: 65535·scale overflows in the decoder's float32, so it is refused.
  const std::vector<float> huge = {-3e38f, 3e38f};
  std::vector<char> bytes(4);
  std::vector<float> scale(1), offset(1);
  const auto refused = encode_fixed16(huge, 1, bytes, scale, offset);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kOutOfRange);
  // No points: zero scale and offset.
  const Fixed16 none = encode({}, 3);
  EXPECT_EQ(none.scale, std::vector<float>(3, 0.0f));
  EXPECT_EQ(none.max_error, 0.0f);
}

TEST(Fixed16, RefusesNonFiniteValuesNamingThem) {
  std::vector<float> values(9, 1.0f);
  values[5] = std::numeric_limits<float>::infinity();
  std::vector<char> bytes(18);
  std::vector<float> scale(3), offset(3);
  const auto r = encode_fixed16(values, 3, bytes, scale, offset);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kOutOfRange);
  EXPECT_NE(r.error().message.find("point 1, channel 2 is infinite"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace animspace::point_codec
