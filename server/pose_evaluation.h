// The pose pipeline: every pose the daemon evaluates — EvaluateKeyPoints' batch, a
// StreamKeyPoints frame, CompleteMiss, a thumbnail's pose — takes these steps, written once. The
// server decodes, batches, encodes and records; what a pose's answer is, every kind of subspace
// decides behind one interface (core/pmsc/subspace.h), built once when the model version loaded:
//
//   decode       server/pose_input.h: key values, check values, engine input, full values
//   estimate     Subspace::estimate, eq. 2 for the pose alone
//   reconstruct  Subspace::reconstruct, batched with every pose waiting for the same model
//                version (server/pose_batcher.h) and written straight into the answer's float32
//                bytes
//   finish       Subspace::finish: the verdict (eqs. 8–11) and each region's, fail-through to
//                the model's engine (whole or local), the blend
//   encode       points, or coordinates the client reconstructs
//   record       the statistics, and a blend or miss appended to the model's miss log
//
// A pose asked for as POINT_ENCODING_COORDINATES skips the batch: its estimate is computed when it
// finishes, and only a pose whose answer the server must compute itself (a blend or miss with an
// engine input or full values) is reconstructed, alone.
#pragma once

#include <span>
#include <string>

#include <Eigen/Core>
#include <grpcpp/support/status.h>

#include "animspace/v1/poses.pb.h"
#include "core/pmsc/pmsc_model.h"
#include "server/model_registry.h"
#include "server/pose_batcher.h"
#include "server/pose_input.h"
#include "server/service_environment.h"

namespace animspace::server {

class CallControl;

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
  // Test traffic (skip_miss_log on the wire): a blend or miss is served but not logged.
  bool log_misses = true;
};

// One pose: its decoded input and options (the caller fills both), and the pipeline's state.
class PoseJob {
 public:
  PoseInput input;
  PoseOptions options;

  // Whether the pose was appended to the miss log (after PoseRun::finish), and if a blend or
  // miss was not, why (the miss log's error).
  bool logged() const { return logged_; }
  const std::string& not_logged_reason() const { return not_logged_reason_; }

 private:
  friend class PoseRun;
  pmsc::PoseEstimate estimate_;
  bool batched_ = false;      // waits in the batcher (whole-pose answer, not coordinates)
  float* points_ = nullptr;   // f̂ (N·D), then the answer
  bool in_response_ = false;  // points_ is the response's own float32 bytes
  Eigen::VectorXf scratch_;   // the points when they cannot go straight into the response
  bool logged_ = false;
  std::string not_logged_reason_;
};

// Evaluates decoded jobs of one model version into their results (same order).
class PoseRun {
 public:
  PoseRun() = default;
  PoseRun(const PoseRun&) = delete;
  PoseRun& operator=(const PoseRun&) = delete;

  // Starts the estimate and reconstruction: the batched jobs wait in the batcher together (and
  // with any other caller's poses for this model version) until finish(). `model`, `jobs` and
  // `results` must stay put until finish() or this run's destruction (which withdraws what
  // still waits).
  void start(ServiceEnvironment& env, const LoadedModel& model, std::span<PoseJob> jobs,
             std::span<v1::PoseResult* const> results);

  // Awaits the batch, then finishes and records every job in order. Stops at the first error —
  // INVALID_ARGUMENT naming `full_points` when partial full values (CompleteMiss) miss a point
  // that needs the full calculation, checked before that pose is counted or logged — or when
  // `call` (optional) was cancelled or ran past its deadline.
  grpc::Status finish(const CallControl* call = nullptr);

 private:
  grpc::Status finish_one(PoseJob& job, v1::PoseResult* out);

  ServiceEnvironment* env_ = nullptr;
  const LoadedModel* model_ = nullptr;
  std::span<PoseJob> jobs_;
  std::span<v1::PoseResult* const> results_;
  // Last: destroyed first, taking the poses out of the batcher before the memory they write goes.
  PoseBatcher::Group group_;
};

// Whether a pose's whole evaluation is smaller than a hand-off to the pool (a request or stream
// frame may then be evaluated on the gRPC thread that received it): an answer as coordinates — no
// f̂ to reconstruct — without an engine input (no full calculation on a miss) and without local
// fail-through (which assembles points). A blend or miss still appends to the miss log there: one
// write (and an fsync with --miss-log-fsync always).
bool evaluated_in_place(v1::PointEncoding points_encoding, bool local_fail_through, const v1::KeyPointPose& pose);

// One pose alone through the pipeline (CompleteMiss, thumbnails); `logged` (optional) says
// whether it was appended to the miss log, `not_logged_reason` (optional) why a blend or miss was
// not. Errors: PoseRun::finish's.
grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged = nullptr,
                           std::string* not_logged_reason = nullptr);

}  // namespace animspace::server
