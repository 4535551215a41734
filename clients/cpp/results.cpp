// Decoding the wire's packed point arrays (float32, or a 16-bit PointEncoding) into plain results,
// and encoding poses.
#include <bit>
#include <cstring>
#include <stdexcept>

#include "clients/cpp/client.h"

namespace animspace {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

const char* cache_status_name(v1::CacheStatus status) {
  switch (status) {
    case v1::CACHE_STATUS_HIT: return "HIT";
    case v1::CACHE_STATUS_BLEND: return "BLEND";
    case v1::CACHE_STATUS_MISS: return "MISS";
    default: return "UNSPECIFIED";
  }
}

namespace {

// The values of the points `indices` of a full frame, in that order; `what` names the caller in
// the error for a frame of the wrong size.
std::vector<float> gather_points(const KeyPoints& keys, const std::vector<uint32_t>& indices,
                                 std::span<const float> frame, const char* what) {
  const size_t needed = size_t{keys.control_point_count} * keys.channel_count;
  if (frame.size() != needed) {
    throw std::invalid_argument(std::string(what) + ": the frame holds " + std::to_string(frame.size()) +
                                " values, expected " + std::to_string(keys.control_point_count) + " points × " +
                                std::to_string(keys.channel_count) + " channels");
  }
  std::vector<float> out;
  out.reserve(indices.size() * keys.channel_count);
  for (uint32_t index : indices) {
    const float* point = frame.data() + size_t{index} * keys.channel_count;
    out.insert(out.end(), point, point + keys.channel_count);
  }
  return out;
}

}  // namespace

std::vector<float> KeyPoints::gather(std::span<const float> frame) const {
  return gather_points(*this, indices, frame, "KeyPoints::gather");
}

std::vector<float> KeyPoints::gather_check_values(std::span<const float> frame) const {
  return gather_points(*this, check_point_indices, frame, "KeyPoints::gather_check_values");
}

namespace {

// IEEE-754 binary16 → float32, exact. Written here rather than taken from core/common/point_codec.h
// because the client library depends only on the generated stubs; tests/clients checks the two
// agree on every pattern.
float half_to_float(uint16_t half) {
  const uint32_t sign = (uint32_t{half} & 0x8000u) << 16;
  const uint32_t exponent = (uint32_t{half} >> 10) & 0x1Fu;
  const uint32_t fraction = uint32_t{half} & 0x3FFu;
  if (exponent == 0x1Fu) {  // Inf, or NaN quieted
    return std::bit_cast<float>(sign | 0x7F80'0000u | (fraction != 0 ? 0x0040'0000u | (fraction << 13) : 0u));
  }
  if (exponent == 0) {  // ±0 or a subnormal: fraction·2^-24, exact in float32
    return std::bit_cast<float>(sign | std::bit_cast<uint32_t>(static_cast<float>(fraction) * 0x1p-24f));
  }
  return std::bit_cast<float>(sign | ((exponent + 127 - 15) << 23) | (fraction << 13));
}

[[noreturn]] void malformed(const std::string& why) {
  // The server checks its own answers; a mismatch means a broken peer, not a user error.
  throw std::runtime_error("malformed PointArray from the server: " + why);
}

}  // namespace

Points decode_points(const v1::PointArray& array) {
  Points out;
  out.point_count = array.point_count();
  out.channel_count = array.channel_count();
  out.max_error = array.max_error();
  const size_t count = size_t{out.point_count} * out.channel_count;
  const v1::PointEncoding encoding = array.encoding();
  const bool float32 = encoding == v1::POINT_ENCODING_UNSPECIFIED || encoding == v1::POINT_ENCODING_FLOAT32;
  if (!float32 && encoding != v1::POINT_ENCODING_FLOAT16 && encoding != v1::POINT_ENCODING_FIXED16) {
    malformed("unknown PointEncoding " + std::to_string(static_cast<int>(encoding)) + " (a newer server?)");
  }
  const size_t expected = count * (float32 ? sizeof(float) : sizeof(uint16_t));
  if (array.data().size() != expected) {
    malformed(std::to_string(out.point_count) + " points × " + std::to_string(out.channel_count) + " channels need " +
              std::to_string(expected) + " bytes, got " + std::to_string(array.data().size()));
  }
  out.values.resize(count);
  if (float32) {
    if (expected > 0) std::memcpy(out.values.data(), array.data().data(), expected);
    return out;
  }
  std::vector<uint16_t> q(count);
  if (expected > 0) std::memcpy(q.data(), array.data().data(), expected);
  if (encoding == v1::POINT_ENCODING_FLOAT16) {
    for (size_t i = 0; i < count; ++i) out.values[i] = half_to_float(q[i]);
    return out;
  }
  const uint32_t channels = out.channel_count;
  if (static_cast<uint32_t>(array.scale_size()) != channels || static_cast<uint32_t>(array.offset_size()) != channels) {
    malformed("FIXED16 needs " + std::to_string(channels) + " scales and offsets (one per channel), got " +
              std::to_string(array.scale_size()) + " and " + std::to_string(array.offset_size()));
  }
  for (size_t i = 0; i < count; ++i) {
    const int c = static_cast<int>(i % channels);
    // common.proto: value = offset[c] + scale[c]·q, two float32 roundings (as the server measured).
    const float step = array.scale(c) * static_cast<float>(q[i]);
    out.values[i] = array.offset(c) + step;
  }
  return out;
}

PoseResult decode_pose_result(const v1::PoseResult& result) {
  PoseResult out;
  if (result.has_points()) out.points = decode_points(result.points());
  out.status = result.status();
  out.key_point_error = result.key_point_error();
  out.key_point_max_error = result.key_point_max_error();
  out.check_point_error = result.check_point_error();
  out.error_estimate = result.error_estimate();
  out.checked = result.checked();
  out.pose_scale = result.pose_scale();
  out.blend_weight = result.blend_weight();
  out.model_version = result.model_version();
  out.full_evaluation_needed = result.full_evaluation_needed();
  out.sequence = result.sequence();
  out.full_points.assign(result.full_points().begin(), result.full_points().end());
  out.full_point_blend_weights.assign(result.full_point_blend_weights().begin(),
                                      result.full_point_blend_weights().end());
  out.region_errors.reserve(static_cast<size_t>(result.region_errors_size()));
  for (const auto& region : result.region_errors()) {
    out.region_errors.push_back({region.region(), region.key_point_error(), region.status()});
  }
  if (result.has_coordinates()) {
    const v1::SubspaceCoordinates& c = result.coordinates();
    out.coordinates.present = true;
    out.coordinates.p.assign(c.p().begin(), c.p().end());
    out.coordinates.basis_checksum = c.basis_checksum();
    out.coordinates.rotation.assign(c.rotation().begin(), c.rotation().end());
    out.coordinates.translation.assign(c.translation().begin(), c.translation().end());
  }
  return out;
}

v1::SkeletonPose encode_skeleton_pose(const SkeletonPose& pose) {
  if (pose.transforms.size() % 12 != 0) {
    throw std::invalid_argument("SkeletonPose.transforms holds " + std::to_string(pose.transforms.size()) +
                                " floats, expected 12 per bone");
  }
  v1::SkeletonPose out;
  out.set_space(pose.space);
  out.set_bone_count(static_cast<uint32_t>(pose.transforms.size() / 12));
  out.set_transforms(pose.transforms.data(), pose.transforms.size() * sizeof(float));
  return out;
}

v1::KeyPointPose encode_key_point_pose(const KeyPointPose& pose) {
  if (pose.channel_count == 0 || pose.key_values.size() % pose.channel_count != 0) {
    throw std::invalid_argument("KeyPointPose.key_values holds " + std::to_string(pose.key_values.size()) +
                                " floats, not a whole number of " + std::to_string(pose.channel_count) + "-channel points");
  }
  v1::KeyPointPose out;
  if (!pose.key_values.empty() || pose.lights.empty()) {
    *out.mutable_key_values() = make_point_array(
        pose.key_values.data(), static_cast<uint32_t>(pose.key_values.size() / pose.channel_count), pose.channel_count);
  }
  if (!pose.check_values.empty()) {
    if (pose.check_values.size() % pose.channel_count != 0) {
      throw std::invalid_argument("KeyPointPose.check_values holds " + std::to_string(pose.check_values.size()) +
                                  " floats, not a whole number of " + std::to_string(pose.channel_count) +
                                  "-channel points");
    }
    *out.mutable_check_values() =
        make_point_array(pose.check_values.data(), static_cast<uint32_t>(pose.check_values.size() / pose.channel_count),
                         pose.channel_count);
  }
  if (pose.skeleton_pose != nullptr) *out.mutable_skeleton_pose() = encode_skeleton_pose(*pose.skeleton_pose);
  for (const PointLight& light : pose.lights) {
    v1::PointLight* encoded = out.mutable_light_set()->add_lights();
    for (double x : light.position) encoded->add_position(x);
    for (double c : light.intensity) encoded->add_intensity(c);
  }
  return out;
}

}  // namespace animspace
