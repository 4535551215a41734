// Fuzz target: request validation (server/validation.h) on requests parsed from arbitrary wire
// bytes, in the order the services run it (server/services/pose_service.cpp,
// skinning_service.cpp): model reference, batch size, response size, then every pose — key
// values and optional skeleton pose for EvaluateKeyPoints, skeleton poses for
// EvaluateSkeletonPose — against the small fixed model of fuzz/request_fixture.h.
//
// Refusals must name the field they were given (STYLE.md: messages name the offending field);
// accepted values must be exactly what the model needs: K·D finite values, one finite affine
// transform per bone.
#include <string>

#include "animspace/v1/poses.pb.h"
#include "animspace/v1/skinning.pb.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/request_fixture.h"
#include "server/validation.h"

namespace animspace::fuzz {
namespace {

namespace fixture = request_fixture;

void check_refusal(const grpc::Status& status, std::string_view field) {
  FUZZ_CHECK(status.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
             status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED);
  FUZZ_CHECK(std::string_view(status.error_message()).starts_with(field));
}

// The checks before any pose: true when the services would go on to decode the poses.
bool check_request_shape(const v1::ModelRef& model, int pose_count, uint64_t bytes_per_pose) {
  if (const grpc::Status s = server::check_model_ref(model, "model"); !s.ok()) check_refusal(s, "model");
  if (const grpc::Status s = server::check_batch_size(pose_count, fixture::kMaxBatch, "poses"); !s.ok()) {
    check_refusal(s, "poses");
    return false;
  }
  const int64_t max_bytes = fixture::kMaxMessageBytes;
  if (const grpc::Status s = server::check_response_size(pose_count, bytes_per_pose, max_bytes, "poses"); !s.ok()) {
    check_refusal(s, "poses");
    return false;
  }
  return true;
}

void check_skeleton_pose(const v1::SkeletonPose& pose, const std::string& field) {
  static const animation_space::Skeleton skeleton = fixture::skeleton();
  animation_space::TransformList globals;
  if (const grpc::Status s = server::decode_skeleton_pose(pose, field, skeleton, globals); !s.ok()) {
    check_refusal(s, field);
    return;
  }
  FUZZ_CHECK(globals.size() == skeleton.parents.size());
  for (const animation_space::Transform& G : globals) {
    FUZZ_CHECK(G.allFinite());
    FUZZ_CHECK(G.row(3) == Eigen::RowVector4d(0, 0, 0, 1));
  }
}

void validate(const v1::EvaluateKeyPointsRequest& request) {
  const uint64_t bytes_per_pose = request.omit_points() ? 0 : uint64_t{4} * fixture::kVertices * fixture::kChannels;
  if (!check_request_shape(request.model(), request.poses_size(), bytes_per_pose)) return;
  for (int i = 0; i < request.poses_size(); ++i) {
    const v1::KeyPointPose& pose = request.poses(i);
    const std::string field = "poses[" + std::to_string(i) + "]";
    Eigen::VectorXf key_values;
    const grpc::Status s = server::decode_points(pose.key_values(), field + ".key_values", fixture::kKeyPoints,
                                                 fixture::kChannels, "key points", key_values);
    if (s.ok()) {
      FUZZ_CHECK(key_values.size() == int64_t{fixture::kKeyPoints} * fixture::kChannels);
      FUZZ_CHECK(key_values.allFinite());
    } else {
      check_refusal(s, field + ".key_values");
    }
    if (pose.has_check_values()) {
      Eigen::VectorXf check_values;
      const grpc::Status c = server::decode_points(pose.check_values(), field + ".check_values",
                                                   fixture::kCheckPoints, fixture::kChannels, "check points",
                                                   check_values);
      if (c.ok()) {
        FUZZ_CHECK(check_values.size() == int64_t{fixture::kCheckPoints} * fixture::kChannels);
        FUZZ_CHECK(check_values.allFinite());
      } else {
        check_refusal(c, field + ".check_values");
      }
    }
    if (pose.has_skeleton_pose()) check_skeleton_pose(pose.skeleton_pose(), field + ".skeleton_pose");
  }
}

void validate(const v1::EvaluateSkeletonPoseRequest& request) {
  const uint64_t bytes_per_pose = uint64_t{12} * fixture::kVertices * (request.include_normals() ? 2 : 1);
  if (!check_request_shape(request.model(), request.poses_size(), bytes_per_pose)) return;
  for (int i = 0; i < request.poses_size(); ++i) {
    check_skeleton_pose(request.poses(i), "poses[" + std::to_string(i) + "]");
  }
}

template <typename Request>
void parse_and_validate(const uint8_t* data, size_t size) {
  Request request;
  if (request.ParseFromArray(data, static_cast<int>(size))) validate(request);
}

}  // namespace
}  // namespace animspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace animspace;
  if (size == 0) return 0;
  if (data[0] == fuzz::request_fixture::kSkeletonPoseRequest) {
    fuzz::parse_and_validate<v1::EvaluateSkeletonPoseRequest>(data + 1, size - 1);
  } else {
    fuzz::parse_and_validate<v1::EvaluateKeyPointsRequest>(data + 1, size - 1);
  }
  return 0;
}
