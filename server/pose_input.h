// A pose's inputs as a request carries them, decoded and checked against the served model: key
// values, check values (issue #35), the input of the model's server engine (a skeleton pose or a
// light set, core/model/engine.h), and CompleteMiss's full values. The first step of the pose
// pipeline (server/pose_evaluation.h); every path that evaluates poses decodes them here.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <grpcpp/support/status.h>

#include "animspace/v1/poses.pb.h"
#include "core/model/engine.h"
#include "server/model_registry.h"

namespace animspace::server {

// A pose's inputs, decoded and checked. The engine input (globals or lights) is read only when
// has_engine_input: the pose carried the input its model's engine takes.
struct PoseInput : model::EngineInput {
  Eigen::VectorXf key_values;  // K·D
  // C·D in check-point order (issue #35), or empty: the pose came without check values and its
  // verdict rests on e_key alone (pmsc::verdict_thresholds).
  Eigen::VectorXf check_values;
  bool has_engine_input = false;
  Eigen::VectorXf full_values;  // from CompleteMiss: N·D, or |full_points|·D; else empty
  std::vector<int> full_points;  // CompleteMiss with local fail-through: the points of full_values
};

// OK for a PMSC model, or FAILED_PRECONDITION naming the model's kind and `why` the call needs
// PMSC (default: key points; a model with a skeleton is pointed at EvaluateSkeletonPose).
grpc::Status require_pmsc(const LoadedModel& model, std::string_view why = {});

// Whether decoding `pose` gathers its key values on the server (a light set without key values):
// milliseconds of ray tracing, for the request pool, not a transport thread.
inline bool gathers_keys(const v1::KeyPointPose& pose) { return pose.has_light_set() && !pose.has_key_values(); }

// Decodes `pose` (named `field` in messages, e.g. "poses[3]"). A skeleton pose or a light set is
// accepted only for a model whose engine takes it; check values only for a model with check
// points (decode_check_values). A light set without key values has them (and the check values)
// computed by the engine at those points.
grpc::Status decode_pose(const LoadedModel& model, const v1::KeyPointPose& pose, const std::string& field,
                         PoseInput& out);

// Decodes a pose's check values `field` (e.g. "poses[3].check_values") into `out`: unset or empty
// (point_count 0, no data) is no check values, `out` empty; else exactly C×D finite values
// (decode_points' refusals, "expected 4 check points, got 3"). INVALID_ARGUMENT when the model
// has no check points (C = 0: cross-PMSC, or trained before issue #35).
grpc::Status decode_check_values(const LoadedModel& model, bool present, const v1::PointArray& values,
                                 const std::string& field, Eigen::VectorXf& out);

// Decodes the full values `field` of a pose whose key (and check) values are decoded
// (CompleteMiss, the heat-map thumbnail) and checks that they are that pose: INVALID_ARGUMENT
// naming the field and the first key or check point where they differ
// (pmsc::check_full_values_at_keys, check_full_values_at_checks). Not for cross-PMSC.
grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const Eigen::VectorXf& check_values,
                                Eigen::VectorXf& out);

// The same for partial full values (local fail-through): `points` (decoded, ascending) names the
// points `values` holds, |points|×D; only the key and check points among them can be checked.
grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const Eigen::VectorXf& check_values,
                                const std::vector<int>& points, Eigen::VectorXf& out);

}  // namespace animspace::server
