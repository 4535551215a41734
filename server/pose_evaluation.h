// One pose through a served PMSC model: decode and check the client's values, evaluate the soft
// cache (Meyer & Anderson 2007 §2.4), fail through to the server's posing engine when the model
// has one and the pose carries a skeleton (FAIL_THROUGH_SERVER), record the outcome in the
// statistics and append every blend or miss to the model's miss log. Shared by the unary, the
// streaming and the CompleteMiss RPCs so that the three answer a pose identically.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <grpcpp/support/status.h>

#include "animspace/v1/poses.pb.h"
#include "core/animspace/skeleton.h"
#include "core/illumination/surface.h"
#include "core/pmsc/pmsc_model.h"
#include "server/model_registry.h"
#include "server/pose_batcher.h"
#include "server/service_environment.h"

namespace animspace::server {

// A pose's inputs, decoded and checked.
struct PoseInput {
  Eigen::VectorXf key_values;                // K·D
  // C·D in check-point order (issue #35), or empty: the pose came without check values and its
  // verdict rests on e_key alone (pmsc::verdict_thresholds).
  Eigen::VectorXf check_values;
  bool has_skeleton = false;
  animation_space::TransformList globals;    // G_j, when has_skeleton
  std::vector<illumination::PointLight> lights;  // the frame's lights (illumination engine), else empty
  Eigen::VectorXf full_values;               // from CompleteMiss: N·D, or |full_points|·D; else empty
  std::vector<int> full_points;              // CompleteMiss with local fail-through: the points of full_values
};

// OK for a PMSC model, or FAILED_PRECONDITION naming the model's kind and `why` the call needs
// PMSC (default: key points; a model with a skeleton is pointed at EvaluateSkeletonPose).
grpc::Status require_pmsc(const LoadedModel& model, std::string_view why = {});

// Whether decoding `pose` gathers its key values on the server (a light set without key values):
// milliseconds of ray tracing, for the request pool, not a transport thread.
inline bool gathers_keys(const v1::KeyPointPose& pose) { return pose.has_light_set() && !pose.has_key_values(); }

// Decodes `pose` (named `field` in messages, e.g. "poses[3]"). A skeleton pose is accepted only
// for a model with a posing engine, a light set only for one with an illumination engine; check
// values only for a model with check points (decode_check_values).
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

struct PoseOptions {
  bool include_region_errors = false;
  // Local fail-through (core/pmsc/local_fail_through.h): report the points that need the full
  // calculation and compute or blend only those. Implied by partial full values (full_points).
  bool local_fail_through = false;
  bool omit_points = false;
  // The encoding of the answer's points (checked by the RPC: check_points_encoding).
  v1::PointEncoding points_encoding = v1::POINT_ENCODING_UNSPECIFIED;
  // CompleteMiss answers a pose that EvaluateKeyPoints already counted: log it, don't count it.
  bool count_in_statistics = true;
};

// The batched path (server/pose_batcher.h), for a pose that `batchable` accepts:
//   prepare_pose  — where f̂ goes; enqueue the returned pose in the batcher, await it;
//   finish_pose   — the verdict, fail-through, blend, statistics and miss log, as evaluate_pose.
struct PendingPose {
  pmsc::PoseEstimate estimate;
  float* points = nullptr;   // f̂ (N·D), then the answer
  bool in_response = false;  // points is the response's own points.data
  Eigen::VectorXf scratch;   // the points when they cannot go straight into the response
};

// Everything but local fail-through, whose answer is assembled point by point.
bool batchable(const PoseInput& input, const PoseOptions& options);

// Points the pose's f̂ at the response's points.data (sized for N·D float32) when the answer
// goes out as float32, else at pending.scratch. `input`, `out` and `pending` must stay put until
// finish_pose.
PoseBatcher::Pose prepare_pose(const LoadedModel& model, const PoseInput& input, const PoseOptions& options,
                               v1::PoseResult* out, PendingPose& pending);

grpc::Status finish_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                         const PoseOptions& options, PendingPose& pending, v1::PoseResult* out, bool* logged = nullptr);

// Evaluates one decoded pose into `out` (through the batcher, with whatever else is waiting); `logged` (optional) says whether it was appended to the
// miss log. INVALID_ARGUMENT naming `full_points` when partial full values (CompleteMiss) miss a
// point that needs the full calculation — checked before anything is counted or logged; OK else.
grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged = nullptr);

}  // namespace animspace::server
