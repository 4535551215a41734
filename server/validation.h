// Request validation: every field a client sends is checked here before any core code sees it,
// and a refusal names the field with the expected and the actual value
// ("poses[3].key_values.point_count: expected 60, got 59"). Nothing is allocated from a size
// the client claims until that size has been checked against the model.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <google/protobuf/repeated_field.h>
#include <grpcpp/support/status.h>

#include "animspace/v1/common.pb.h"
#include "animspace/v1/poses.pb.h"
#include "core/animspace/skeleton.h"
#include "core/illumination/surface.h"

namespace animspace::server {

// The model reference: a valid name (see validate_model_name). `field` is e.g. "model".
grpc::Status check_model_ref(const v1::ModelRef& ref, std::string_view field);

// Batch size: INVALID_ARGUMENT for an empty batch, RESOURCE_EXHAUSTED above `max_batch`.
grpc::Status check_batch_size(int size, uint32_t max_batch, std::string_view field);

// The answer to `count` entries of about `bytes_per_entry` each must fit in one message:
// RESOURCE_EXHAUSTED naming `field`, the size and the limit otherwise (checked before any work).
grpc::Status check_response_size(int count, uint64_t bytes_per_entry, int64_t max_message_bytes,
                                 std::string_view field);

// A PointArray of exactly `points` × `channels` values in any PointEncoding (float32, FLOAT16,
// FIXED16 with its D scales and offsets), decoded into `out` as float32 (points·channels values,
// point-major) and each finite. `what_points` names the points in messages ("key points",
// "points"); a refusal names the member ("<field>.scale: expected 3 values (one per channel) for
// FIXED16, got 1").
grpc::Status decode_points(const v1::PointArray& array, std::string_view field, uint32_t points,
                           uint32_t channels, std::string_view what_points, Eigen::VectorXf& out);

// Point indices (`field`, e.g. "full_points"): strictly ascending (no repeats), each below
// `point_count` — the layout of a partial frame (local fail-through). Decoded into `out`.
grpc::Status decode_point_indices(const google::protobuf::RepeatedField<uint32_t>& indices, std::string_view field,
                                  uint32_t point_count, std::vector<int>& out);

// A skeleton pose for `skeleton`, as global transforms G_j (local poses are composed down the
// hierarchy, Merry 2007 §2.2).
grpc::Status decode_skeleton_pose(const v1::SkeletonPose& pose, std::string_view field,
                                  const animation_space::Skeleton& skeleton, animation_space::TransformList& globals);

// A light set for an illumination engine (Meyer & Anderson 2007 §3.2): 1..kMaxLights lights,
// each with a 3-value position and a 3-value or empty intensity (empty: `default_intensity`, the
// model's training intensity); values checked by illumination::check_lights.
inline constexpr int kMaxLights = 64;
grpc::Status decode_light_set(const v1::LightSet& set, std::string_view field, const Eigen::Vector3d& default_intensity,
                              std::vector<illumination::PointLight>& out);

// Packs `points`·`channels` floats into a PointArray as float32.
void encode_points(const float* values, uint32_t points, uint32_t channels, v1::PointArray* out);

// The same in `encoding` (checked by check_points_encoding), encoded straight into the message's
// bytes (core/common/point_codec.h) with `max_error` set. OUT_OF_RANGE naming `points_encoding`
// when the values cannot be carried (FLOAT16 beyond ±65504): never clamped; `out` is then cleared.
grpc::Status encode_points(const float* values, uint32_t points, uint32_t channels, v1::PointEncoding encoding,
                           v1::PointArray* out);

// A request's encoding for its answer (`field`, e.g. "points_encoding"): INVALID_ARGUMENT for a
// value this server does not know (proto3 enums are open).
grpc::Status check_points_encoding(v1::PointEncoding encoding, std::string_view field);

// Bytes per value on the wire: 4 for float32 (and for coordinates, whose answers may be points the
// server computed), 2 for the 16-bit encodings.
uint64_t bytes_per_value(v1::PointEncoding encoding);

// "FLOAT16", … for messages.
const char* encoding_name(v1::PointEncoding encoding);

}  // namespace animspace::server
