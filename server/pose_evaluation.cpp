#include "server/pose_evaluation.h"

#include <chrono>
#include <vector>

#include <spdlog/spdlog.h>

#include "core/pmsc/coordinates.h"
#include "core/pmsc/local_fail_through.h"
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
void write_verdict(const LoadedModel& model, const PoseOptions& options, const pmsc::CachedPose& cached,
                   v1::PoseResult* out) {
  const pmsc::PmscModel& m = *model.pmsc;
  out->set_status(to_proto(cached.status));
  out->set_key_point_error(static_cast<float>(cached.key_point_error));
  out->set_check_point_error(static_cast<float>(cached.check_point_error));
  out->set_error_estimate(static_cast<float>(cached.error_estimate));
  if (m.relative_tolerance) out->set_pose_scale(static_cast<float>(cached.scale));
  out->set_checked(cached.checked);
  out->set_blend_weight(static_cast<float>(cached.alpha));
  out->set_model_version(model.version);
  out->set_full_evaluation_needed(cached.full_evaluation_needed);
  if (!options.include_region_errors) return;
  for (size_t r = 0; r < cached.region_errors.size(); ++r) {
    auto* region = out->add_region_errors();
    region->set_region(static_cast<uint32_t>(r));
    region->set_key_point_error(static_cast<float>(cached.region_errors[r]));
    // The verdict local fail-through acts on: each region against its own thresholds — or, for a
    // pose without check values of a model with check points, the whole pose's (its regions are
    // calibrated for estimates that include check points; local_fail_through.h).
    const auto& thresholds = pmsc::region_thresholds(m, static_cast<int>(r));
    const bool regional = cached.checked || m.check_points.empty();
    region->set_status(regional ? to_proto(pmsc::decide(cached.region_errors[r], thresholds).status)
                                : to_proto(cached.status));
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
// client sent or the engine computed (a partial frame on the local path). Returns whether it
// was appended; a failed append leaves the answer right and is logged loudly.
bool log_miss(ServiceEnvironment& env, const LoadedModel& model, const PoseJob& job, const pmsc::CachedPose& cached,
              const pmsc::LocalFailThrough& local) {
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
    const std::vector<int>& points = client_full ? input.full_points : local.full_points;
    if (local_path(job)) record.full_points.assign(points.begin(), points.end());
  }
  auto appended = env.miss_logs.append(model.name, *model.pmsc, record);
  if (!appended) {
    // The answer is still right; only the retraining data is short. Say so loudly.
    spdlog::error("miss log of {}: cannot append: {}", model.name, appended.error().message);
    return false;
  }
  return true;
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
    // Local fail-through assembles its answer point by point; coordinates need no f̂ unless the
    // verdict asks the server for the answer (finish_one).
    job.batched_ = !local_path(job) && !wants_coordinates(job.options);
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
  env.batcher.enqueue(*model.pmsc, batched, group_);
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
  const pmsc::PmscModel& m = *model.pmsc;
  const PoseInput& input = job.input;
  const Eigen::VectorXf* client_full = input.full_values.size() > 0 ? &input.full_values : nullptr;
  pmsc::CachedPose cached;
  pmsc::LocalFailThrough local;
  const float* answer = nullptr;
  bool coordinates = false;
  if (job.batched_) {
    Eigen::Map<Eigen::VectorXf> points(job.points_, m.mean.size());
    pmsc::finish_cached(m, job.estimate_, points, client_full, full_calculation(model, input), cached);
    answer = job.points_;
  } else if (local_path(job)) {
    if (auto covered = pmsc::evaluate_cached_local(m, input.key_values, input.check_values, input.full_points,
                                                   client_full, partial_calculation(model, input), cached, local);
        !covered.ok()) {
      return to_grpc_status(covered.error(), "full_points");
    }
    answer = cached.points.data();
  } else {
    // Coordinates: eq. 2 alone; f̂ only when the server itself must answer with points.
    pmsc::estimate_coordinates(m, input.key_values, input.check_values, job.estimate_);
    const bool needs_full = pmsc::judge(m, job.estimate_, cached);
    if (needs_full && (client_full != nullptr || input.has_engine_input)) {
      job.scratch_.resize(m.mean.size());
      const pmsc::PoseEstimate* estimate = &job.estimate_;
      float* destination = job.scratch_.data();
      pmsc::reconstruct(m, {&estimate, 1}, {&destination, 1});
      pmsc::finish_cached(m, job.estimate_, job.scratch_, client_full, full_calculation(model, input), cached);
      answer = job.scratch_.data();
    } else {
      cached.full_evaluation_needed = needs_full;
      coordinates = true;
    }
  }

  write_verdict(model, job.options, cached, out);
  if (coordinates) {
    if (!job.options.omit_points) write_coordinates(model, job.estimate_, out);
  } else if (job.in_response_) {
    out->mutable_points()->set_point_count(static_cast<uint32_t>(m.point_count));
    out->mutable_points()->set_channel_count(static_cast<uint32_t>(m.channel_count));
  } else if (!job.options.omit_points) {
    if (grpc::Status s = encode_points(answer, static_cast<uint32_t>(m.point_count),
                                       static_cast<uint32_t>(m.channel_count), job.options.points_encoding,
                                       out->mutable_points());
        !s.ok()) {
      return s;
    }
  }
  for (size_t j = 0; j < local.full_points.size(); ++j) {
    out->add_full_points(static_cast<uint32_t>(local.full_points[j]));
    out->add_full_point_blend_weights(static_cast<float>(local.full_point_blend_weights[j]));
  }
  if (job.options.count_in_statistics) env_->metrics.record_pose(model.name, cached.status, cached.key_point_error);
  if (cached.status != pmsc::CacheStatus::kHit) job.logged_ = log_miss(*env_, model, job, cached, local);
  return grpc::Status::OK;
}

bool evaluated_in_place(v1::PointEncoding points_encoding, bool local_fail_through, const v1::KeyPointPose& pose) {
  return points_encoding == v1::POINT_ENCODING_COORDINATES && !local_fail_through && !pose.has_skeleton_pose() &&
         !pose.has_light_set();
}

grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged) {
  PoseJob job;
  job.input = input;
  job.options = options;
  PoseRun run;
  run.start(env, model, {&job, 1}, {&out, 1});
  grpc::Status status = run.finish();
  if (logged != nullptr) *logged = job.logged();
  return status;
}

}  // namespace animspace::server
