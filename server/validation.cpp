#include "server/validation.h"

#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <span>
#include <utility>

#include "core/common/point_codec.h"

#include "server/model_registry.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

// The wire format is little-endian float32 (common.proto); this build copies bytes as they are.
static_assert(std::endian::native == std::endian::little, "animspaced assumes a little-endian host");

std::string join(std::string_view field, std::string_view member) {
  return std::string(field) + "." + std::string(member);
}

std::span<const float> floats(const google::protobuf::RepeatedField<float>& field) {
  return {field.data(), static_cast<size_t>(field.size())};
}

}  // namespace

grpc::Status check_model_ref(const v1::ModelRef& ref, std::string_view field) {
  if (auto valid = validate_model_name(ref.name(), join(field, "name")); !valid) {
    return to_grpc_status(valid.error());
  }
  return grpc::Status::OK;
}

grpc::Status check_batch_size(int size, uint32_t max_batch, std::string_view field) {
  if (size == 0) {
    return invalid_argument(std::string(field) + ": empty batch, expected 1.." + std::to_string(max_batch) +
                            " entries");
  }
  if (static_cast<uint64_t>(size) > max_batch) {
    return resource_exhausted(std::string(field) + ": " + std::to_string(size) + " entries, the limit is " +
                              std::to_string(max_batch) + " (--max-batch-poses); split the batch");
  }
  return grpc::Status::OK;
}

grpc::Status check_response_size(int count, uint64_t bytes_per_entry, int64_t max_message_bytes,
                                 std::string_view field) {
  // Field tags, lengths and the small members of each entry: a generous allowance.
  constexpr uint64_t kOverheadPerEntry = 64;
  const uint64_t bytes = static_cast<uint64_t>(count) * (bytes_per_entry + kOverheadPerEntry);
  if (bytes > static_cast<uint64_t>(max_message_bytes)) {
    return resource_exhausted(std::string(field) + ": the response to " + std::to_string(count) +
                              " entries would be about " + std::to_string(bytes) + " bytes, the limit is " +
                              std::to_string(max_message_bytes) + " (--max-message-bytes); send fewer per request");
  }
  return grpc::Status::OK;
}

grpc::Status decode_points(const v1::PointArray& array, std::string_view field, uint32_t points,
                           uint32_t channels, std::string_view what_points, Eigen::VectorXf& out) {
  if (array.point_count() != points) {
    return invalid_argument(join(field, "point_count") + ": expected " + std::to_string(points) + " " +
                            std::string(what_points) + ", got " + std::to_string(array.point_count()));
  }
  if (array.channel_count() != channels) {
    return invalid_argument(join(field, "channel_count") + ": expected " + std::to_string(channels) + ", got " +
                            std::to_string(array.channel_count()));
  }
  if (grpc::Status s = check_points_encoding(array.encoding(), join(field, "encoding")); !s.ok()) return s;
  const v1::PointEncoding encoding = array.encoding();
  if (encoding == v1::POINT_ENCODING_COORDINATES) {
    return invalid_argument(join(field, "encoding") +
                            ": POINT_ENCODING_COORDINATES is for answers only; send FLOAT32, FLOAT16 or FIXED16 values");
  }
  const bool fixed16 = encoding == v1::POINT_ENCODING_FIXED16;
  // scale and offset belong to FIXED16 alone: on another array they mean the encoding was forgotten.
  for (const auto& [member, parameters] : {std::pair{"scale", &array.scale()}, std::pair{"offset", &array.offset()}}) {
    if (!fixed16 && !parameters->empty()) {
      return invalid_argument(join(field, member) + ": only FIXED16 arrays carry one; this one is " +
                              std::string(encoding_name(encoding)) + " (set encoding = POINT_ENCODING_FIXED16?)");
    }
    if (fixed16 && static_cast<uint64_t>(parameters->size()) != channels) {
      return invalid_argument(join(field, member) + ": expected " + std::to_string(channels) +
                              " values (one per channel) for FIXED16, got " + std::to_string(parameters->size()));
    }
    for (int c = 0; c < parameters->size(); ++c) {
      if (!std::isfinite(parameters->Get(c))) {
        return invalid_argument(join(field, member) + "[" + std::to_string(c) + "]: " +
                                (std::isnan(parameters->Get(c)) ? "NaN" : "infinite") + "; expected a finite value");
      }
    }
  }
  const uint64_t values = uint64_t{points} * channels;
  const uint64_t width = bytes_per_value(encoding);
  if (array.data().size() != values * width) {
    const std::string named = width == 2 ? std::string(", ") + encoding_name(encoding) : std::string();
    return invalid_argument(join(field, "data") + ": expected " + std::to_string(values * width) + " bytes (" +
                            std::to_string(width) + " · " + std::to_string(points) + " · " + std::to_string(channels) +
                            named + "), got " + std::to_string(array.data().size()));
  }
  out.resize(static_cast<Eigen::Index>(values));
  const std::span<float> decoded(out.data(), values);
  if (encoding == v1::POINT_ENCODING_FLOAT16) {
    point_codec::decode_float16(array.data(), decoded);
  } else if (fixed16) {
    point_codec::decode_fixed16(array.data(), floats(array.scale()), floats(array.offset()), decoded);
  } else if (values > 0) {
    std::memcpy(out.data(), array.data().data(), array.data().size());
  }
  // Decoded values too: a float16 Inf pattern, or a FIXED16 scale and offset that overflow.
  if (!out.allFinite()) {
    for (Eigen::Index i = 0; i < out.size(); ++i) {
      if (std::isfinite(out[i])) continue;
      return invalid_argument(join(field, "data") + ": value of point " + std::to_string(i / channels) +
                              ", channel " + std::to_string(i % channels) + " is " +
                              (std::isnan(out[i]) ? "NaN" : "infinite") + "; expected finite values");
    }
  }
  return grpc::Status::OK;
}

grpc::Status decode_point_indices(const google::protobuf::RepeatedField<uint32_t>& indices, std::string_view field,
                                  uint32_t point_count, std::vector<int>& out) {
  out.clear();
  out.reserve(static_cast<size_t>(indices.size()));
  for (int j = 0; j < indices.size(); ++j) {
    const uint32_t index = indices.Get(j);
    const std::string entry = std::string(field) + "[" + std::to_string(j) + "]";
    if (index >= point_count) {
      return invalid_argument(entry + ": expected a point index below " + std::to_string(point_count) +
                              " (the model's points), got " + std::to_string(index));
    }
    if (j > 0 && index <= indices.Get(j - 1)) {
      return invalid_argument(entry + ": expected an index above " + std::string(field) + "[" +
                              std::to_string(j - 1) + "] = " + std::to_string(indices.Get(j - 1)) +
                              " (ascending, no repeats), got " + std::to_string(index));
    }
    out.push_back(static_cast<int>(index));
  }
  return grpc::Status::OK;
}

grpc::Status decode_skeleton_pose(const v1::SkeletonPose& pose, std::string_view field,
                                  const animation_space::Skeleton& skeleton, animation_space::TransformList& globals) {
  const auto bones = static_cast<uint32_t>(skeleton.parents.size());
  if (pose.space() != v1::SkeletonPose::SPACE_LOCAL && pose.space() != v1::SkeletonPose::SPACE_GLOBAL) {
    return invalid_argument(join(field, "space") + ": expected SPACE_LOCAL or SPACE_GLOBAL, got " +
                            std::to_string(static_cast<int>(pose.space())));
  }
  if (pose.bone_count() != bones) {
    return invalid_argument(join(field, "bone_count") + ": expected " + std::to_string(bones) + ", got " +
                            std::to_string(pose.bone_count()));
  }
  const size_t expected_bytes = size_t{bones} * 12 * sizeof(float);
  if (pose.transforms().size() != expected_bytes) {
    return invalid_argument(join(field, "transforms") + ": expected " + std::to_string(expected_bytes) +
                            " bytes (4 · 12 · " + std::to_string(bones) + " bones), got " +
                            std::to_string(pose.transforms().size()));
  }
  animation_space::TransformList transforms(bones, animation_space::Transform::Identity());
  const char* bytes = pose.transforms().data();
  for (uint32_t j = 0; j < bones; ++j) {
    float rows[12];
    std::memcpy(rows, bytes + size_t{j} * sizeof(rows), sizeof(rows));
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        const float value = rows[r * 4 + c];
        if (!std::isfinite(value)) {
          return invalid_argument(join(field, "transforms") + ": bone " + std::to_string(j) + ", entry (" +
                                  std::to_string(r) + "," + std::to_string(c) + ") is " +
                                  (std::isnan(value) ? "NaN" : "infinite") + "; expected finite values");
        }
        transforms[j](r, c) = value;
      }
    }
  }
  globals = pose.space() == v1::SkeletonPose::SPACE_LOCAL ? animation_space::global_transforms(skeleton, transforms)
                                                         : std::move(transforms);
  if (auto valid = animation_space::validate_pose(skeleton, globals, join(field, "transforms")); !valid) {
    return to_grpc_status(valid.error());
  }
  return grpc::Status::OK;
}

grpc::Status decode_light_set(const v1::LightSet& set, std::string_view field, const Eigen::Vector3d& default_intensity,
                              std::vector<illumination::PointLight>& out) {
  const std::string lights = join(field, "lights");
  if (set.lights_size() < 1 || set.lights_size() > kMaxLights) {
    return invalid_argument(lights + ": expected 1 to " + std::to_string(kMaxLights) + " lights, got " +
                            std::to_string(set.lights_size()));
  }
  out.clear();
  for (int i = 0; i < set.lights_size(); ++i) {
    const v1::PointLight& light = set.lights(i);
    const std::string name = lights + "[" + std::to_string(i) + "]";
    if (light.position_size() != 3) {
      return invalid_argument(name + ".position: expected 3 values (x, y, z), got " +
                              std::to_string(light.position_size()));
    }
    if (light.intensity_size() != 0 && light.intensity_size() != 3) {
      return invalid_argument(name + ".intensity: expected 3 values (R, G, B) or none (the model's training "
                                     "intensity), got " + std::to_string(light.intensity_size()));
    }
    illumination::PointLight decoded;
    decoded.position = Eigen::Vector3d(light.position(0), light.position(1), light.position(2));
    decoded.intensity = light.intensity_size() == 3
                            ? Eigen::Vector3d(light.intensity(0), light.intensity(1), light.intensity(2))
                            : default_intensity;
    out.push_back(decoded);
  }
  if (auto valid = illumination::check_lights(out, lights, kMaxLights); !valid.ok()) {
    return to_grpc_status(valid.error());
  }
  return grpc::Status::OK;
}

void encode_points(const float* values, uint32_t points, uint32_t channels, v1::PointArray* out) {
  out->set_point_count(points);
  out->set_channel_count(channels);
  out->set_data(values, size_t{points} * channels * sizeof(float));
}

grpc::Status encode_points(const float* values, uint32_t points, uint32_t channels, v1::PointEncoding encoding,
                           v1::PointArray* out) {
  if (encoding == v1::POINT_ENCODING_COORDINATES) {
    // Points the server computed itself, asked for as coordinates: they go out as float32.
    encode_points(values, points, channels, out);
    out->set_encoding(v1::POINT_ENCODING_FLOAT32);
    return grpc::Status::OK;
  }
  if (encoding == v1::POINT_ENCODING_UNSPECIFIED || encoding == v1::POINT_ENCODING_FLOAT32) {
    encode_points(values, points, channels, out);
    out->set_encoding(encoding);
    return grpc::Status::OK;
  }
  assert(encoding == v1::POINT_ENCODING_FLOAT16 || encoding == v1::POINT_ENCODING_FIXED16);
  out->set_point_count(points);
  out->set_channel_count(channels);
  out->set_encoding(encoding);
  const size_t count = size_t{points} * channels;
  const std::span<const float> input(values, count);
  // Straight into the message's bytes: no intermediate buffer for a large answer.
  std::string* data = out->mutable_data();
  data->resize(2 * count);
  const std::span<char> bytes(data->data(), data->size());
  Result<float> max_error = 0.0f;
  if (encoding == v1::POINT_ENCODING_FLOAT16) {
    max_error = point_codec::encode_float16(input, channels, bytes);
  } else {
    out->mutable_scale()->Resize(static_cast<int>(channels), 0.0f);
    out->mutable_offset()->Resize(static_cast<int>(channels), 0.0f);
    max_error = point_codec::encode_fixed16(input, channels, bytes, {out->mutable_scale()->mutable_data(), channels},
                                            {out->mutable_offset()->mutable_data(), channels});
  }
  if (!max_error.ok()) {
    Error error = max_error.error();
    error.message = "points_encoding: " + std::string(encoding_name(encoding)) + " cannot carry this answer: " +
                    error.message +
                    (encoding == v1::POINT_ENCODING_FLOAT16 ? "; ask for POINT_ENCODING_FIXED16 or FLOAT32" : "");
    out->Clear();
    return to_grpc_status(error);
  }
  out->set_max_error(*max_error);
  return grpc::Status::OK;
}

uint64_t bytes_per_value(v1::PointEncoding encoding) {
  return encoding == v1::POINT_ENCODING_FLOAT16 || encoding == v1::POINT_ENCODING_FIXED16 ? 2 : 4;
}

const char* encoding_name(v1::PointEncoding encoding) {
  switch (encoding) {
    case v1::POINT_ENCODING_UNSPECIFIED: return "float32 (encoding unset)";
    case v1::POINT_ENCODING_FLOAT32: return "FLOAT32";
    case v1::POINT_ENCODING_FLOAT16: return "FLOAT16";
    case v1::POINT_ENCODING_FIXED16: return "FIXED16";
    case v1::POINT_ENCODING_COORDINATES: return "COORDINATES";
    default: return "an unknown encoding";
  }
}

grpc::Status check_points_encoding(v1::PointEncoding encoding, std::string_view field) {
  // proto3 enums are open: a newer client's value arrives as a plain number.
  if (v1::PointEncoding_IsValid(encoding)) return grpc::Status::OK;
  return invalid_argument(std::string(field) + ": unknown PointEncoding " + std::to_string(static_cast<int>(encoding)) +
                          "; expected POINT_ENCODING_FLOAT32 (or unset), POINT_ENCODING_FLOAT16, "
                          "POINT_ENCODING_FIXED16 or POINT_ENCODING_COORDINATES");
}

}  // namespace animspace::server
