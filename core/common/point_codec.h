// Compact encodings of point arrays (the wire's PointEncoding, proto/animspace/v1/common.proto):
// IEEE-754 binary16 ("half") and per-channel 16-bit fixed point, both little-endian, 2 bytes a
// value, half the size of float32. Pure functions over caller-owned buffers, so that the server
// encodes straight into a message's bytes without an intermediate copy.
//
// Every encoder returns the exact largest |decoded − value| over the array: the client is told how
// much the compact answer lost instead of being told a bound. Encoders refuse values they cannot
// represent (NaN, ±Inf, and for binary16 magnitudes above 65504) rather than clamp them.
//
// Values are a flat point-major array: N points × D channels, value i is point i / D, channel
// i % D (the layout of PointArray.data and of PointMatrix's storage).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/common/result.h"

namespace animspace::point_codec {

// ---- IEEE-754 binary16 -------------------------------------------------------------------

// The largest finite binary16 value, (2 − 2^-10)·2^15. The encoder refuses any |v| above it:
// round-to-nearest-even would send [65520, ∞) to ±Inf and (65504, 65520) to 65504, i.e. clamp.
inline constexpr float kMaxFloat16 = 65504.0f;

// Which implementation converts between float32 and binary16. The two give bit-identical
// results (tests/core/common/point_codec_test.cpp checks it); kAuto takes F16C when this CPU and
// OS have it (one vcvtps2ph per 8 values) and the portable scalar code otherwise.
enum class HalfConversion { kAuto, kScalar, kF16c };

// True when the CPU has F16C and the OS saves AVX state (the F16C path is usable).
bool f16c_available();

// One float32 → binary16 bit pattern, rounded to nearest, ties to even; exact for the half
// subnormals (multiples of 2^-24 below 2^-14). Total IEEE conversion: magnitudes ≥ 65520 give
// ±Inf and NaN stays NaN (quieted, payload truncated, as F16C does) — the range check is the
// encoder's job, not this function's.
uint16_t float_to_half(float value);
// One binary16 bit pattern → float32 (always exact; a NaN comes back quieted).
float half_to_float(uint16_t half);

// Encodes `values` into `out` (2·values.size() bytes), each value rounded to nearest even.
// Returns the largest |decoded − value| (exact: a float32 minus its binary16 rounding is itself
// a float32), or kOutOfRange naming the first value that is not finite or exceeds ±kMaxFloat16
// (by point and channel, with `channels` = D ≥ 1); `out` is then unspecified.
// Error bound: ≤ 2^-11·|v| for |v| ≥ 2^-14, ≤ 2^-25 below.
Result<float> encode_float16(std::span<const float> values, size_t channels, std::span<char> out,
                             HalfConversion conversion = HalfConversion::kAuto);

// Decodes 2·out.size() bytes of `in` into `out`. Inf and NaN patterns decode as such: the caller
// checks that the values are finite when it needs them to be.
void decode_float16(std::span<const char> in, std::span<float> out,
                    HalfConversion conversion = HalfConversion::kAuto);

// ---- Per-channel 16-bit fixed point ---------------------------------------------------------

// value = offset[c] + scale[c]·q, q a uint16, evaluated in float32 as written (scale·q rounded,
// then the sum rounded) by every decoder — this one, the C++ client's and numpy's.
//
// The encoder takes, for each channel c over all points:
//   offset[c] = min_c,
//   scale[c]  = (max_c − min_c)/65535, rounded up to float32 (so 65535·scale[c] ≥ max_c − min_c
//               and every q lands in [0, 65535]); 0 when max_c == min_c (every q is 0 and the
//               channel decodes exactly),
//   q         = round((v − offset[c])/scale[c]), computed in double (halves round up).
// Error bound for every value v of channel c (stated here, checked by brute force in the tests):
//   |decoded − v| ≤ scale[c]/2 + 2^-23·(max_c − min_c + max(|min_c|, |max_c|)),
// the quantisation's half step plus the two float32 roundings of the decoder.
//
// Writes `scale` and `offset` (D = channels values each) and `out` (2·values.size() bytes); returns
// the largest |decoded − value| over the array, rounded up to float32 (the smallest float32 not
// below the exact maximum), or kOutOfRange naming the first value that is not finite, or a channel
// whose range decodes beyond float32 (values near ±3.4e38 of both signs).
Result<float> encode_fixed16(std::span<const float> values, size_t channels, std::span<char> out,
                             std::span<float> scale, std::span<float> offset);

// Decodes 2·out.size() bytes of `in` into `out`, with D = channels = scale.size() = offset.size().
// The result may overflow to ±Inf for a scale and offset the encoder never writes: the caller
// checks that the values are finite when it needs them to be.
void decode_fixed16(std::span<const char> in, std::span<const float> scale, std::span<const float> offset,
                    std::span<float> out);

}  // namespace animspace::point_codec
