#include "core/common/point_codec.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <cpuid.h>
#include <immintrin.h>

#include "core/common/format.h"

namespace animspace::point_codec {
namespace {

// binary16 fields: 1 sign bit, 5 exponent bits (bias 15), 10 fraction bits.
constexpr uint32_t kFloatAbsMask = 0x7FFF'FFFFu;
constexpr uint32_t kFloatInf = 0x7F80'0000u;
constexpr uint16_t kHalfInf = 0x7C00u;
constexpr uint16_t kHalfQuietBit = 0x0200u;
// |v| ≥ 65520 (half-way between 65504 and 2^16, a tie that goes to the even 2^16) overflows.
constexpr uint32_t kFloatHalfOverflow = 0x477F'F000u;
// 2^-14, the smallest normal half.
constexpr uint32_t kFloatHalfMinNormal = 0x3880'0000u;
// 2^-25, half the smallest subnormal half: at or below it everything rounds to ±0.
constexpr uint32_t kFloatHalfUnderflow = 0x3300'0000u;
// Exponent rebias from float32 (127) to binary16 (15), in place in a float32's bits.
constexpr uint32_t kRebias = (127u - 15u) << 23;

std::string where(size_t index, size_t channels) {
  return "value of point " + std::to_string(index / channels) + ", channel " + std::to_string(index % channels);
}

// The first value binary16 cannot carry, as an error (the F16C path finds that there is one with
// one mask for the whole array, then asks here which).
Error unencodable_as_float16(std::span<const float> values, size_t channels) {
  for (size_t i = 0; i < values.size(); ++i) {
    const float v = values[i];
    if (!std::isfinite(v)) {
      return make_error(ErrorCode::kOutOfRange,
                        where(i, channels) + " is " + (std::isnan(v) ? "NaN" : "infinite") + "; expected finite values");
    }
    if (std::fabs(v) > kMaxFloat16) {
      return make_error(ErrorCode::kOutOfRange, where(i, channels) + " is " + format_number(v) +
                                                    ", beyond ±65504, the largest float16");
    }
  }
  return make_error(ErrorCode::kInternal, "float16 encoding refused an array with no unencodable value");
}

bool encode_float16_scalar(std::span<const float> values, char* out, float& max_error) {
  float worst = 0.0f;
  for (size_t i = 0; i < values.size(); ++i) {
    const float v = values[i];
    // Negated so that NaN is refused too.
    if (!(std::fabs(v) <= kMaxFloat16)) return false;
    const uint16_t h = float_to_half(v);
    std::memcpy(out + 2 * i, &h, sizeof h);
    worst = std::max(worst, std::fabs(half_to_float(h) - v));
  }
  max_error = worst;
  return true;
}

void decode_float16_scalar(const char* in, std::span<float> out) {
  for (size_t i = 0; i < out.size(); ++i) {
    uint16_t h;
    std::memcpy(&h, in + 2 * i, sizeof h);
    out[i] = half_to_float(h);
  }
}

// F16C: 8 values per instruction. Bytes move through memcpy (one unaligned load or store) so
// that no pointer is cast to a vector type of stricter alignment. The last < 8 values go through
// a zero-padded block, so every value takes the same instruction as the others.
__attribute__((target("avx,f16c"))) __m256 f16c_encode_block(const float* values, char* out, __m256& refused) {
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFF'FFFF));
  const __m256 v = _mm256_loadu_ps(values);
  const __m128i h = _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT);
  std::memcpy(out, &h, sizeof h);
  // Not-less-or-equal, unordered: true for |v| > 65504, ±Inf and NaN.
  refused = _mm256_or_ps(refused, _mm256_cmp_ps(_mm256_and_ps(v, abs_mask), _mm256_set1_ps(kMaxFloat16), _CMP_NLE_UQ));
  return _mm256_and_ps(_mm256_sub_ps(_mm256_cvtph_ps(h), v), abs_mask);
}

__attribute__((target("avx,f16c"))) bool encode_float16_f16c(std::span<const float> values, char* out,
                                                             float& max_error) {
  __m256 refused = _mm256_setzero_ps();
  __m256 worst = _mm256_setzero_ps();
  size_t i = 0;
  for (; i + 8 <= values.size(); i += 8) {
    worst = _mm256_max_ps(worst, f16c_encode_block(values.data() + i, out + 2 * i, refused));
  }
  if (const size_t rest = values.size() - i; rest > 0) {
    float block[8] = {};
    char bytes[16];
    std::copy_n(values.data() + i, rest, block);
    worst = _mm256_max_ps(worst, f16c_encode_block(block, bytes, refused));
    std::memcpy(out + 2 * i, bytes, 2 * rest);
  }
  if (_mm256_movemask_ps(refused) != 0) return false;
  float lanes[8];
  _mm256_storeu_ps(lanes, worst);
  max_error = *std::max_element(lanes, lanes + 8);
  return true;
}

__attribute__((target("avx,f16c"))) void decode_float16_f16c(const char* in, std::span<float> out) {
  size_t i = 0;
  for (; i + 8 <= out.size(); i += 8) {
    __m128i h;
    std::memcpy(&h, in + 2 * i, sizeof h);
    _mm256_storeu_ps(out.data() + i, _mm256_cvtph_ps(h));
  }
  if (const size_t rest = out.size() - i; rest > 0) {
    __m128i h = _mm_setzero_si128();
    std::memcpy(&h, in + 2 * i, 2 * rest);
    float block[8];
    _mm256_storeu_ps(block, _mm256_cvtph_ps(h));
    std::copy_n(block, rest, out.data() + i);
  }
}

bool cpu_has_f16c() {
#if defined(__clang__)
  // Clang 14's __builtin_cpu_supports does not know "f16c": CPUID leaf 1, ECX bit 29.
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  return __get_cpuid(1, &eax, &ebx, &ecx, &edx) != 0 && (ecx & bit_F16C) != 0;
#else
  return __builtin_cpu_supports("f16c");
#endif
}

bool use_f16c(HalfConversion conversion) {
  assert(conversion != HalfConversion::kF16c || f16c_available());
  return conversion == HalfConversion::kF16c || (conversion == HalfConversion::kAuto && f16c_available());
}

// The decoders' formula, in one place so that the encoder's error is the decoders' error: two
// float32 roundings, written as two statements (the build does not contract them into an FMA:
// no -ffast-math, no FMA in the target's baseline ISA).
float fixed16_value(float scale, float offset, uint16_t q) {
  const float step = scale * static_cast<float>(q);
  return offset + step;
}

// |a − b| rounded up to float32. The double difference of two floats may itself be rounded (when
// their exponents lie far apart), so its rounding error r (Knuth's TwoSum: d + r == a − b
// exactly) decides the last step up.
float abs_difference_rounded_up(float a, float b) {
  const double x = a;
  const double y = -static_cast<double>(b);
  const double d = x + y;
  const double y_part = d - x;
  const double r = (x - (d - y_part)) + (y - y_part);
  const double magnitude = std::fabs(d);
  float rounded = static_cast<float>(magnitude);
  const bool exact_above = static_cast<double>(rounded) < magnitude ||
                           (static_cast<double>(rounded) == magnitude && r != 0.0 && (r > 0.0) == (d > 0.0));
  if (exact_above) rounded = std::nextafter(rounded, std::numeric_limits<float>::infinity());
  return rounded;
}

}  // namespace

bool f16c_available() {
  // "avx" also checks that the OS saves the YMM registers (XGETBV).
  static const bool available = __builtin_cpu_supports("avx") && cpu_has_f16c();
  return available;
}

uint16_t float_to_half(float value) {
  const uint32_t bits = std::bit_cast<uint32_t>(value);
  const auto sign = static_cast<uint16_t>((bits >> 16) & 0x8000u);
  const uint32_t abs = bits & kFloatAbsMask;
  if (abs >= kFloatInf) {
    // Inf stays Inf; NaN keeps its top 10 fraction bits and is quieted (F16C does the same).
    const uint32_t nan = abs > kFloatInf ? kHalfQuietBit | ((abs >> 13) & 0x3FFu) : 0u;
    return static_cast<uint16_t>(sign | kHalfInf | nan);
  }
  if (abs >= kFloatHalfOverflow) return static_cast<uint16_t>(sign | kHalfInf);
  if (abs >= kFloatHalfMinNormal) {
    // Normal: drop 13 fraction bits, rounding to nearest even by adding just under half of the
    // dropped unit (plus one when the kept part is odd). A carry out of the fraction moves into
    // the exponent, which is the correct rounding up to the next binade.
    const uint32_t odd = (abs >> 13) & 1u;
    return static_cast<uint16_t>(sign | ((abs + 0x0FFFu + odd - kRebias) >> 13));
  }
  if (abs <= kFloatHalfUnderflow) return sign;
  // Subnormal half: q = round(|v| / 2^-24). |v| = m·2^(e−150) with the implicit bit in m, so
  // q = m / 2^(126−e), the shift being 14..24 in this range. q = 1024 is the smallest normal
  // (0x0400), which is again the correct pattern.
  const uint32_t exponent = abs >> 23;
  const uint32_t mantissa = (abs & 0x007F'FFFFu) | 0x0080'0000u;
  const uint32_t shift = 126u - exponent;
  uint32_t q = mantissa >> shift;
  const uint32_t remainder = mantissa & ((1u << shift) - 1u);
  const uint32_t half_unit = 1u << (shift - 1u);
  if (remainder > half_unit || (remainder == half_unit && (q & 1u) != 0u)) ++q;
  return static_cast<uint16_t>(sign | q);
}

float half_to_float(uint16_t half) {
  const uint32_t sign = (uint32_t{half} & 0x8000u) << 16;
  const uint32_t exponent = (uint32_t{half} >> 10) & 0x1Fu;
  const uint32_t fraction = uint32_t{half} & 0x3FFu;
  if (exponent == 0x1Fu) {
    const uint32_t nan = fraction != 0 ? 0x0040'0000u | (fraction << 13) : 0u;
    return std::bit_cast<float>(sign | kFloatInf | nan);
  }
  if (exponent == 0) {
    // ±0 or a subnormal, fraction·2^-24: exact in float32.
    const float magnitude = static_cast<float>(fraction) * 0x1p-24f;
    return std::bit_cast<float>(sign | std::bit_cast<uint32_t>(magnitude));
  }
  return std::bit_cast<float>(sign | ((exponent << 23) + kRebias) | (fraction << 13));
}

Result<float> encode_float16(std::span<const float> values, size_t channels, std::span<char> out,
                             HalfConversion conversion) {
  assert(channels >= 1 && out.size() == 2 * values.size());
  float max_error = 0.0f;
  const bool encoded = use_f16c(conversion) ? encode_float16_f16c(values, out.data(), max_error)
                                            : encode_float16_scalar(values, out.data(), max_error);
  if (!encoded) return unencodable_as_float16(values, channels);
  return max_error;
}

void decode_float16(std::span<const char> in, std::span<float> out, HalfConversion conversion) {
  assert(in.size() == 2 * out.size());
  if (use_f16c(conversion)) {
    decode_float16_f16c(in.data(), out);
  } else {
    decode_float16_scalar(in.data(), out);
  }
}

Result<float> encode_fixed16(std::span<const float> values, size_t channels, std::span<char> out,
                             std::span<float> scale, std::span<float> offset) {
  assert(channels >= 1 && values.size() % channels == 0 && out.size() == 2 * values.size());
  assert(scale.size() == channels && offset.size() == channels);
  // Phase 1: every value finite; each channel's min (in offset) and max (in scale, for now). One
  // channel at a time with the extremes in registers: this loop runs over every fixed16 answer.
  bool finite = true;
  for (size_t c = 0; c < channels; ++c) {
    float low = std::numeric_limits<float>::infinity(), high = -low;
    for (size_t i = c; i < values.size(); i += channels) {
      const float v = values[i];
      finite = finite && std::isfinite(v);
      low = std::min(low, v);
      high = std::max(high, v);
    }
    offset[c] = low;
    scale[c] = high;
  }
  if (!finite) {
    for (size_t i = 0; i < values.size(); ++i) {
      if (!std::isfinite(values[i])) {
        return make_error(ErrorCode::kOutOfRange, where(i, channels) + " is " +
                                                      (std::isnan(values[i]) ? "NaN" : "infinite") +
                                                      "; expected finite values");
      }
    }
  }
  // Phase 2: the step of each channel, rounded up so that 65535 steps cover its range. The
  // range is taken in double: max − min of two float32 may exceed FLT_MAX.
  for (size_t c = 0; c < channels; ++c) {
    if (values.empty()) {
      offset[c] = 0.0f;
      scale[c] = 0.0f;
      continue;
    }
    const double range = static_cast<double>(scale[c]) - static_cast<double>(offset[c]);
    float step = static_cast<float>(range / 65535.0);
    if (static_cast<double>(step) * 65535.0 < range) step = std::nextafter(step, std::numeric_limits<float>::infinity());
    scale[c] = step;
  }
  // Phase 3: quantise, and measure what the decoder will give back. This is the per-value loop of
  // every fixed16 answer the server sends, so it is kept to arithmetic: (v − min)/step ≥ 0, so
  // rounding to nearest is ⌊x + ½⌋ (halves go up), and the error is taken exactly in double (the
  // difference of two floats is exact unless their exponents lie 29 binades apart); only the
  // largest is rounded up to float32 at the end.
  double worst = 0.0;
  size_t worst_at = 0;
  for (size_t c = 0; c < channels; ++c) {
    const double low = offset[c];
    const double inverse = scale[c] > 0.0f ? 1.0 / static_cast<double>(scale[c]) : 0.0;
    for (size_t i = c; i < values.size(); i += channels) {
      const float v = values[i];
      // (v − min) ≤ range ≤ 65535·step: x ≤ 65535 up to the product's rounding.
      const double x = (static_cast<double>(v) - low) * inverse;
      const auto bits = static_cast<uint16_t>(std::min(x + 0.5, 65535.0));
      std::memcpy(out.data() + 2 * i, &bits, sizeof bits);
      const float decoded = fixed16_value(scale[c], offset[c], bits);
      finite = finite && std::isfinite(decoded);
      const double difference = std::fabs(static_cast<double>(decoded) - static_cast<double>(v));
      if (difference > worst) {
        worst = difference;
        worst_at = i;
      }
    }
  }
  if (!finite) {
    for (size_t i = 0; i < values.size(); ++i) {
      const size_t c = i % channels;
      uint16_t bits;
      std::memcpy(&bits, out.data() + 2 * i, sizeof bits);
      if (!std::isfinite(fixed16_value(scale[c], offset[c], bits))) {
        return make_error(ErrorCode::kOutOfRange, where(i, channels) + " is " + format_number(values[i]) +
                                                      ": channel " + std::to_string(c) +
                                                      "'s range is too wide for fixed16 (it decodes beyond float32)");
      }
    }
  }
  if (worst == 0.0) return 0.0f;
  const size_t c = worst_at % channels;
  uint16_t bits;
  std::memcpy(&bits, out.data() + 2 * worst_at, sizeof bits);
  return abs_difference_rounded_up(fixed16_value(scale[c], offset[c], bits), values[worst_at]);
}

void decode_fixed16(std::span<const char> in, std::span<const float> scale, std::span<const float> offset,
                    std::span<float> out) {
  const size_t channels = scale.size();
  assert(channels >= 1 && offset.size() == channels && out.size() % channels == 0 && in.size() == 2 * out.size());
  for (size_t i = 0; i < out.size(); ++i) {
    uint16_t q;
    std::memcpy(&q, in.data() + 2 * i, sizeof q);
    const size_t c = i % channels;
    out[i] = fixed16_value(scale[c], offset[c], q);
  }
}

}  // namespace animspace::point_codec
