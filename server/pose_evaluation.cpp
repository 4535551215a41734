#include "server/pose_evaluation.h"

#include <chrono>
#include <vector>

#include <spdlog/spdlog.h>

#include "core/pmsc/coordinates.h"
#include "core/pmsc/subspace.h"
#include "server/convert.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

int64_t unix_now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

bool local_path(const PoseJob& job) { return job.options.local_fail_through || !job.input.full_points.empty(); }

bool wants_coordinates(const PoseOptions& options) {
  return options.points_encoding == v1::POINT_ENCODING_COORDINATES;
}

// The model engine's full calculation of the pose (fail-through), when the pose carried the
// engine's input (decode_pose accepted it only for a model whose engine takes it); else none.
pmsc::FullCalculation full_calculation(const LoadedModel& model, const PoseInput& input) {
  if (!input.has_engine_input) return {};
  return [engine = model.engine.get(), &input](Eigen::VectorXf& full) {
    engine->frame(input, full);
    return true;
  };
}

// The same for some points (local fail-through): a point computed alone is the point of the
// whole frame (core/model/engine.h).
pmsc::PartialFullCalculation partial_calculation(const LoadedModel& model, const PoseInput& input) {
  if (!input.has_engine_input) return {};
  return [engine = model.engine.get(), &input](const std::vector<int>& points, Eigen::VectorXf& full) {
    engine->points(input, points, full);
    return true;
  };
}

// The verdict and its numbers, as the wire names them.
void write_verdict(const LoadedModel& model, const PoseOptions& options, const pmsc::PoseAnswer& answer,
                   v1::PoseResult* out) {
  const pmsc::CachedPose& cached = answer.cached;
  out->set_status(to_proto(cached.status));
  out->set_key_point_error(static_cast<float>(cached.key_point_error));
  out->set_key_point_max_error(static_cast<float>(cached.key_point_max_error));
  out->set_check_point_error(static_cast<float>(cached.check_point_error));
  out->set_error_estimate(static_cast<float>(cached.error_estimate));
  if (model.pmsc->relative_tolerance) out->set_pose_scale(static_cast<float>(cached.scale));
  out->set_checked(cached.checked);
  out->set_blend_weight(static_cast<float>(cached.alpha));
  out->set_model_version(model.version);
  out->set_full_evaluation_needed(cached.full_evaluation_needed);
  if (!options.include_region_errors) return;
  for (size_t r = 0; r < cached.region_errors.size(); ++r) {
    auto* region = out->add_region_errors();
    region->set_region(static_cast<uint32_t>(r));
    region->set_key_point_error(static_cast<float>(cached.region_errors[r]));
    region->set_status(to_proto(answer.region_statuses[r]));
  }
}

// The answer as p and the alignment, for the client to reconstruct (pmsc/coordinates.h).
void write_coordinates(const LoadedModel& model, const pmsc::PoseEstimate& estimate, v1::PoseResult* out) {
  auto* coordinates = out->mutable_coordinates();
  auto* p = coordinates->mutable_p();
  p->Resize(static_cast<int>(estimate.coordinates.size()), 0.0f);
  // float, as the server's own reconstruction uses them (pmsc::reconstruct).
  Eigen::Map<Eigen::VectorXf>(p->mutable_data(), estimate.coordinates.size()) = estimate.coordinates.cast<float>();
  coordinates->set_basis_checksum(model.basis_checksum);
  if (!model.pmsc->aligned) return;
  const pmsc::FloatAlignment alignment = pmsc::float_alignment(estimate.alignment);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) coordinates->add_rotation(alignment.rotation(r, c));
    coordinates->add_translation(alignment.translation(r));
  }
}

// Appends a blend or miss to the model's miss log: the key values, and the full values the
// client sent or the engine computed (a partial frame on the local path). A failed append
// leaves the answer right and is logged loudly; its error is returned for the caller to say.
Status log_miss(ServiceEnvironment& env, const LoadedModel& model, const PoseJob& job, const pmsc::PoseAnswer& answer) {
  const pmsc::CachedPose& cached = answer.cached;
  const PoseInput& input = job.input;
  misslog::MissRecord record;
  record.model_version = model.version;
  record.unix_time_us = unix_now_us();
  record.status = cached.status;
  record.key_point_error = cached.key_point_error;
  record.blend_weight = cached.alpha;
  record.channel_count = static_cast<uint32_t>(model.pmsc->channel_count);
  record.key_values.assign(input.key_values.data(), input.key_values.data() + input.key_values.size());
  const bool client_full = input.full_values.size() > 0;
  const Eigen::VectorXf* full = client_full ? &input.full_values
                                            : (cached.computed_full_values.size() > 0 ? &cached.computed_full_values
                                                                                      : nullptr);
  if (full != nullptr) {
    record.full_values.assign(full->data(), full->data() + full->size());
    // A partial frame: the client's points, or those the engine computed.
    const std::vector<int>& points = client_full ? input.full_points : answer.local.full_points;
    if (local_path(job)) record.full_points.assign(points.begin(), points.end());
  }
  auto appended = env.miss_logs.append(model.name, *model.pmsc, record);
  if (!appended) {
    // The answer is still right; only the retraining data is short. Say so loudly.
    if (appended.error().code != ErrorCode::kResourceExhausted) {
      spdlog::error("miss log of {}: cannot append: {}", model.name, appended.error().message);
    }
    return appended.error();
  }
  env.metrics.set_miss_log_bytes(model.name, env.miss_logs.size_bytes(model.name));
  return Status::Ok();
}

}  // namespace

void PoseRun::start(ServiceEnvironment& env, const LoadedModel& model, std::span<PoseJob> jobs,
                    std::span<v1::PoseResult* const> results) {
  env_ = &env;
  model_ = &model;
  jobs_ = jobs;
  results_ = results;
  const auto values = static_cast<size_t>(model.pmsc->mean.size());
  std::vector<PoseBatcher::Pose> batched;
  for (size_t i = 0; i < jobs.size(); ++i) {
    PoseJob& job = jobs[i];
    // Coordinates need no f̂ unless the verdict asks the server for the answer (finish); local
    // fail-through answers with points, whatever the encoding.
    job.batched_ = local_path(job) || !wants_coordinates(job.options);
    if (!job.batched_) continue;
    // float32 goes out as computed: f̂ is reconstructed into the message itself, and the blend of
    // a blend or miss happens there too. A 16-bit encoding is written from the scratch values.
    job.in_response_ = !job.options.omit_points && bytes_per_value(job.options.points_encoding) == sizeof(float);
    if (job.in_response_) {
      std::string* data = results[i]->mutable_points()->mutable_data();
      data->resize(values * sizeof(float));
      job.points_ = reinterpret_cast<float*>(data->data());
    } else {
      job.scratch_.resize(static_cast<long>(values));
      job.points_ = job.scratch_.data();
    }
    batched.push_back({&job.input.key_values, &job.estimate_, job.points_, &job.input.check_values});
  }
  env.batcher.enqueue(*model.subspace, batched, group_);
}

grpc::Status PoseRun::finish(const CallControl* call) {
  env_->batcher.await(group_);
  for (size_t i = 0; i < jobs_.size(); ++i) {
    if (call != nullptr) {
      if (grpc::Status stop = call->stop_status(); !stop.ok()) return stop;
    }
    if (grpc::Status s = finish_one(jobs_[i], results_[i]); !s.ok()) return s;
  }
  return grpc::Status::OK;
}

grpc::Status PoseRun::finish_one(PoseJob& job, v1::PoseResult* out) {
  const LoadedModel& model = *model_;
  const pmsc::Subspace& subspace = *model.subspace;
  const pmsc::PmscModel& m = subspace.model();
  const PoseInput& input = job.input;
  // A pose answered as coordinates skipped the batch: its estimate is computed now.
  if (!job.batched_) subspace.estimate(input.key_values, input.check_values, job.estimate_);
  pmsc::FinishInput finish;
  finish.points = job.batched_ ? job.points_ : nullptr;
  finish.local = local_path(job);
  if (input.full_values.size() > 0) {
    finish.full_values = &input.full_values;
    if (finish.local) finish.full_points = &input.full_points;
  }
  if (finish.local) {
    finish.partial_calculation = partial_calculation(model, input);
  } else {
    finish.full_calculation = full_calculation(model, input);
  }
  pmsc::PoseAnswer answer;
  if (Status finished = subspace.finish(job.estimate_, finish, answer); !finished.ok()) {
    return to_grpc_status(finished.error(), "full_points");
  }

  write_verdict(model, job.options, answer, out);
  if (answer.points == nullptr) {
    if (!job.options.omit_points) write_coordinates(model, job.estimate_, out);
  } else if (answer.points == job.points_ && job.in_response_) {
    out->mutable_points()->set_point_count(static_cast<uint32_t>(m.point_count));
    out->mutable_points()->set_channel_count(static_cast<uint32_t>(m.channel_count));
  } else if (!job.options.omit_points) {
    if (grpc::Status s = encode_points(answer.points, static_cast<uint32_t>(m.point_count),
                                       static_cast<uint32_t>(m.channel_count), job.options.points_encoding,
                                       out->mutable_points());
        !s.ok()) {
      return s;
    }
  }
  for (size_t j = 0; j < answer.local.full_points.size(); ++j) {
    out->add_full_points(static_cast<uint32_t>(answer.local.full_points[j]));
    out->add_full_point_blend_weights(static_cast<float>(answer.local.full_point_blend_weights[j]));
  }
  if (job.options.count_in_statistics) {
    env_->metrics.record_pose(model.name, answer.cached.status, answer.cached.key_point_error);
  }
  if (answer.cached.status == pmsc::CacheStatus::kHit) return grpc::Status::OK;
  if (!job.options.log_misses) {
    job.not_logged_reason_ = "the request set skip_miss_log (test traffic: kept out of retraining)";
    env_->metrics.record_miss_not_logged(model.name, Metrics::NotLogged::kSkipped);
    return grpc::Status::OK;
  }
  const Status appended = log_miss(*env_, model, job, answer);
  job.logged_ = appended.ok();
  if (!appended.ok()) {
    job.not_logged_reason_ = appended.error().message;
    env_->metrics.record_miss_not_logged(model.name, appended.error().code == ErrorCode::kResourceExhausted
                                                         ? Metrics::NotLogged::kFull
                                                         : Metrics::NotLogged::kError);
  }
  return grpc::Status::OK;
}

bool evaluated_in_place(v1::PointEncoding points_encoding, bool local_fail_through, const v1::KeyPointPose& pose) {
  return points_encoding == v1::POINT_ENCODING_COORDINATES && !local_fail_through && !pose.has_skeleton_pose() &&
         !pose.has_light_set();
}

grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged,
                           std::string* not_logged_reason) {
  PoseJob job;
  job.input = input;
  job.options = options;
  PoseRun run;
  run.start(env, model, {&job, 1}, {&out, 1});
  grpc::Status status = run.finish();
  if (logged != nullptr) *logged = job.logged();
  if (not_logged_reason != nullptr) *not_logged_reason = job.not_logged_reason();
  return status;
}

}  // namespace animspace::server
