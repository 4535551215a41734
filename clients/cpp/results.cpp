// Decoding the wire's packed float32 arrays into plain results, and encoding poses.
#include <bit>
#include <cstring>
#include <stdexcept>

#include "clients/cpp/client.h"

namespace animspace {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian float32");

const char* cache_status_name(v1::CacheStatus status) {
  switch (status) {
    case v1::CACHE_STATUS_HIT: return "HIT";
    case v1::CACHE_STATUS_BLEND: return "BLEND";
    case v1::CACHE_STATUS_MISS: return "MISS";
    default: return "UNSPECIFIED";
  }
}

std::vector<float> KeyPoints::gather(std::span<const float> frame) const {
  const size_t needed = size_t{control_point_count} * channel_count;
  if (frame.size() != needed) {
    throw std::invalid_argument("KeyPoints::gather: the frame holds " + std::to_string(frame.size()) +
                                " values, expected " + std::to_string(control_point_count) + " points × " +
                                std::to_string(channel_count) + " channels");
  }
  std::vector<float> out;
  out.reserve(indices.size() * channel_count);
  for (uint32_t index : indices) {
    const float* point = frame.data() + size_t{index} * channel_count;
    out.insert(out.end(), point, point + channel_count);
  }
  return out;
}

Points decode_points(const v1::PointArray& array) {
  Points out;
  out.point_count = array.point_count();
  out.channel_count = array.channel_count();
  const size_t expected = size_t{out.point_count} * out.channel_count * sizeof(float);
  if (array.data().size() != expected) {
    // The server checks its own answers; a mismatch means a broken peer, not a user error.
    throw std::runtime_error("malformed PointArray from the server: " + std::to_string(out.point_count) + " points × " +
                             std::to_string(out.channel_count) + " channels need " + std::to_string(expected) +
                             " bytes, got " + std::to_string(array.data().size()));
  }
  out.values.resize(size_t{out.point_count} * out.channel_count);
  if (expected > 0) std::memcpy(out.values.data(), array.data().data(), expected);
  return out;
}

PoseResult decode_pose_result(const v1::PoseResult& result) {
  PoseResult out;
  if (result.has_points()) out.points = decode_points(result.points());
  out.status = result.status();
  out.key_point_error = result.key_point_error();
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
  if (pose.skeleton_pose != nullptr) *out.mutable_skeleton_pose() = encode_skeleton_pose(*pose.skeleton_pose);
  for (const PointLight& light : pose.lights) {
    v1::PointLight* encoded = out.mutable_light_set()->add_lights();
    for (double x : light.position) encoded->add_position(x);
    for (double c : light.intensity) encoded->add_intensity(c);
  }
  return out;
}

}  // namespace animspace
