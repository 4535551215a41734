#include "server/pose_evaluation.h"

#include <chrono>

#include <spdlog/spdlog.h>

#include "core/animspace/model.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pmsc_model.h"
#include "server/convert.h"
#include "server/model_lookup.h"
#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

int64_t unix_now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

grpc::Status require_pmsc(const LoadedModel& model, std::string_view why) {
  if (model.pmsc) return grpc::Status::OK;
  std::string reason(why);
  if (reason.empty()) {
    reason = "it has no key points to evaluate";
    if (model.animation_space) reason += " (evaluate it with SkinningService.EvaluateSkeletonPose)";
  }
  return unsupported_by_kind(model, reason);
}

grpc::Status decode_pose(const LoadedModel& model, const v1::KeyPointPose& pose, const std::string& field,
                         PoseInput& out) {
  const pmsc::PmscModel& m = *model.pmsc;
  const std::string engine_note =
      m.cross ? "is impossible" : (model.animation_space || model.illumination ? "takes another input"
                                                                                 : "is by the client: send full values with CompleteMiss");
  if (pose.has_light_set()) {
    if (!model.illumination) {
      return {grpc::StatusCode::INVALID_ARGUMENT, field + ".light_set: model '" + model.name +
                                                      "' has no illumination engine on the server (fail-through " +
                                                      engine_note + "); leave light_set unset"};
    }
    if (grpc::Status s = decode_light_set(pose.light_set(), field + ".light_set",
                                          model.illumination->default_intensity(), out.lights);
        !s.ok()) {
      return s;
    }
  }
  if (!out.lights.empty() && !pose.has_key_values()) {
    // The server is the renderer here (Meyer & Anderson 2007 §3.2): it gathers the key points
    // and the check points alone, and the soft cache judges them as it would judge a client's.
    if (pose.has_check_values()) {
      return invalid_argument(field + ".check_values: sent without key_values; the server gathers both for the "
                                      "light_set (send both, or neither)");
    }
    model.illumination->engine->indirect(out.lights, model.illumination->gather, m.key_points, out.key_values);
    if (m.check_point_count() > 0) {
      model.illumination->engine->indirect(out.lights, model.illumination->gather, m.check_points, out.check_values);
    }
  } else if (grpc::Status s = decode_points(pose.key_values(), field + ".key_values",
                                            static_cast<uint32_t>(m.key_point_count()),
                                            static_cast<uint32_t>(m.channel_count), "key points", out.key_values);
             !s.ok()) {
    return s;
  } else if (grpc::Status checks = decode_check_values(model, pose.has_check_values(), pose.check_values(),
                                                       field + ".check_values", out.check_values);
             !checks.ok()) {
    return checks;
  }
  out.has_skeleton = pose.has_skeleton_pose();
  if (!out.has_skeleton) return grpc::Status::OK;
  if (!model.animation_space) {
    return {grpc::StatusCode::INVALID_ARGUMENT,
            field + ".skeleton_pose: model '" + model.name + "' has no posing engine on the server (fail-through " +
                engine_note + "); leave skeleton_pose unset"};
  }
  return decode_skeleton_pose(pose.skeleton_pose(), field + ".skeleton_pose", model.animation_space->skeleton,
                              out.globals);
}

grpc::Status decode_check_values(const LoadedModel& model, bool present, const v1::PointArray& values,
                                 const std::string& field, Eigen::VectorXf& out) {
  const pmsc::PmscModel& m = *model.pmsc;
  out.resize(0);
  // An empty array is no check values, like an unset one: a client may always fill the field
  // from DescribeKeyPoints' (possibly empty) check_point_indices.
  if (!present || (values.point_count() == 0 && values.data().empty())) return grpc::Status::OK;
  if (m.check_point_count() == 0) {
    return invalid_argument(field + ": model '" + model.name + "' version " + std::to_string(model.version) +
                            " has no check points (DescribeKeyPoints lists none); leave check_values unset");
  }
  return decode_points(values, field, static_cast<uint32_t>(m.check_point_count()),
                       static_cast<uint32_t>(m.channel_count), "check points", out);
}

grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const Eigen::VectorXf& check_values,
                                Eigen::VectorXf& out) {
  const pmsc::PmscModel& m = *model.pmsc;
  if (grpc::Status s = decode_points(values, field, static_cast<uint32_t>(m.point_count),
                                     static_cast<uint32_t>(m.channel_count), "points", out);
      !s.ok()) {
    return s;
  }
  // A cross model's key points are another point set: nothing in the output repeats them.
  if (m.cross) return grpc::Status::OK;
  if (auto consistent = pmsc::check_full_values_at_keys(m, key_values, out); !consistent.ok()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, field + ": " + consistent.error().message};
  }
  if (auto consistent = pmsc::check_full_values_at_checks(m, check_values, out); !consistent.ok()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, field + ": " + consistent.error().message};
  }
  return grpc::Status::OK;
}

grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const Eigen::VectorXf& check_values,
                                const std::vector<int>& points, Eigen::VectorXf& out) {
  if (points.empty()) return decode_full_values(model, values, field, key_values, check_values, out);
  const pmsc::PmscModel& m = *model.pmsc;
  if (grpc::Status s = decode_points(values, field, static_cast<uint32_t>(points.size()),
                                     static_cast<uint32_t>(m.channel_count), "points (one per full_points entry)", out);
      !s.ok()) {
    return s;
  }
  if (m.cross) return grpc::Status::OK;
  if (auto consistent = pmsc::check_full_values_at_keys(m, key_values, points, out); !consistent.ok()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, field + ": " + consistent.error().message};
  }
  if (auto consistent = pmsc::check_full_values_at_checks(m, check_values, points, out); !consistent.ok()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, field + ": " + consistent.error().message};
  }
  return grpc::Status::OK;
}

namespace {

// The server's full calculation of a whole pose (fail-through): the posing engine posed at the
// request's skeleton, or the illumination engine gathering for its lights (decode_pose accepted
// each input only for a model that has its engine); empty when the pose brought neither.
pmsc::FullCalculation full_calculation(const LoadedModel& model, const PoseInput& input) {
  if (input.has_skeleton) {
    return [engine = model.animation_space.get(), globals = &input.globals](Eigen::VectorXf& full) {
      PointMatrix posed;
      animation_space::evaluate(*engine, *globals, posed);
      full = Eigen::Map<const Eigen::VectorXf>(posed.data(), posed.size());
      return true;
    };
  }
  if (!input.lights.empty()) {
    return [served = model.illumination.get(), lights = &input.lights](Eigen::VectorXf& full) {
      served->engine->indirect(*lights, served->gather, served->engine->all_points(), full);
      return true;
    };
  }
  return {};
}

// Writes the soft cache's answer into `out` and records it: statistics, and the miss log for a
// blend or miss. `answer` is the answer (N·D); `in_response` says it already lies in out's
// points.data. `local` is empty outside local fail-through.
grpc::Status record_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                         const PoseOptions& options, const pmsc::CachedPose& cached, const float* answer,
                         bool in_response, const pmsc::LocalFailThrough& local, v1::PoseResult* out, bool* logged) {
  if (logged != nullptr) *logged = false;
  const pmsc::PmscModel& m = *model.pmsc;
  const Eigen::VectorXf* client_full = input.full_values.size() > 0 ? &input.full_values : nullptr;
  const bool local_path = options.local_fail_through || !input.full_points.empty();
  out->set_status(to_proto(cached.status));
  out->set_key_point_error(static_cast<float>(cached.key_point_error));
  out->set_check_point_error(static_cast<float>(cached.check_point_error));
  out->set_error_estimate(static_cast<float>(cached.error_estimate));
  out->set_checked(cached.checked);
  out->set_blend_weight(static_cast<float>(cached.alpha));
  out->set_model_version(model.version);
  out->set_full_evaluation_needed(cached.full_evaluation_needed);
  if (in_response) {
    out->mutable_points()->set_point_count(static_cast<uint32_t>(m.point_count));
    out->mutable_points()->set_channel_count(static_cast<uint32_t>(m.channel_count));
  } else if (!options.omit_points) {
    if (grpc::Status s = encode_points(answer, static_cast<uint32_t>(m.point_count),
                                       static_cast<uint32_t>(m.channel_count), options.points_encoding,
                                       out->mutable_points());
        !s.ok()) {
      return s;
    }
  }
  for (size_t j = 0; j < local.full_points.size(); ++j) {
    out->add_full_points(static_cast<uint32_t>(local.full_points[j]));
    out->add_full_point_blend_weights(static_cast<float>(local.full_point_blend_weights[j]));
  }
  if (options.include_region_errors) {
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
  if (options.count_in_statistics) {
    env.metrics.record_pose(model.name, cached.status, cached.key_point_error);
  }
  if (cached.status == pmsc::CacheStatus::kHit) return grpc::Status::OK;

  misslog::MissRecord record;
  record.model_version = model.version;
  record.unix_time_us = unix_now_us();
  record.status = cached.status;
  record.key_point_error = cached.key_point_error;
  record.blend_weight = cached.alpha;
  record.channel_count = static_cast<uint32_t>(m.channel_count);
  record.key_values.assign(input.key_values.data(), input.key_values.data() + input.key_values.size());
  const Eigen::VectorXf* full =
      client_full != nullptr ? client_full
                             : (cached.computed_full_values.size() > 0 ? &cached.computed_full_values : nullptr);
  // A partial frame: the client's points, or those the engine computed.
  const std::vector<int>& points = client_full != nullptr ? input.full_points : local.full_points;
  if (full != nullptr && local_path && !points.empty()) {
    auto version = env.miss_logs.format_version(model.name);
    if (version && *version < misslog::kFirstPartialFormatVersion) {
      // A log created before partial frames: append the frame retraining would complete anyway.
      const Eigen::VectorXf frame = pmsc::complete_partial_frame(m, input.key_values, points, *full);
      record.full_values.assign(frame.data(), frame.data() + frame.size());
    } else {
      record.full_points.assign(points.begin(), points.end());
      record.full_values.assign(full->data(), full->data() + full->size());
    }
  } else if (full != nullptr) {
    record.full_values.assign(full->data(), full->data() + full->size());
  }
  auto appended = env.miss_logs.append(model.name, record);
  if (!appended) {
    // The answer is still right; only the retraining data is short. Say so loudly.
    spdlog::error("miss log of {}: cannot append: {}", model.name, appended.error().message);
    return grpc::Status::OK;
  }
  if (logged != nullptr) *logged = true;
  return grpc::Status::OK;
}


}  // namespace

bool batchable(const PoseInput& input, const PoseOptions& options) {
  return !options.local_fail_through && input.full_points.empty();
}

PoseBatcher::Pose prepare_pose(const LoadedModel& model, const PoseInput& input, const PoseOptions& options,
                               v1::PoseResult* out, PendingPose& pending) {
  const pmsc::PmscModel& m = *model.pmsc;
  const auto values = static_cast<size_t>(m.point_count) * static_cast<size_t>(m.channel_count);
  // float32 goes out as computed; a 16-bit encoding is written from the scratch values.
  pending.in_response = !options.omit_points && bytes_per_value(options.points_encoding) == sizeof(float);
  if (pending.in_response) {
    // f̂ is reconstructed into the message itself, and the blend of a blend or miss happens
    // there too: no copy of the points between the evaluation and serialisation.
    std::string* data = out->mutable_points()->mutable_data();
    data->resize(values * sizeof(float));
    pending.points = reinterpret_cast<float*>(data->data());
  } else {
    pending.scratch.resize(static_cast<long>(values));
    pending.points = pending.scratch.data();
  }
  return {&input.key_values, &pending.estimate, pending.points, &input.check_values};
}

grpc::Status finish_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                         const PoseOptions& options, PendingPose& pending, v1::PoseResult* out, bool* logged) {
  const pmsc::PmscModel& m = *model.pmsc;
  const Eigen::VectorXf* client_full = input.full_values.size() > 0 ? &input.full_values : nullptr;
  Eigen::Map<Eigen::VectorXf> points(pending.points, m.mean.size());
  pmsc::CachedPose cached;
  pmsc::finish_cached(m, pending.estimate, points, client_full, full_calculation(model, input), cached);
  return record_pose(env, model, input, options, cached, pending.points, pending.in_response, {}, out, logged);
}

grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged) {
  if (batchable(input, options)) {
    PendingPose pending;
    const PoseBatcher::Pose pose = prepare_pose(model, input, options, out, pending);
    PoseBatcher::Group group;
    env.batcher.enqueue(*model.pmsc, {&pose, 1}, group);
    env.batcher.await(group);
    return finish_pose(env, model, input, options, pending, out, logged);
  }
  // Local fail-through: the engine computes only the points that need it. Animation space is
  // evaluated vertex by vertex (eq. 3.1), and the gather is per point and deterministic, so a
  // point computed alone is the point of the whole frame.
  const pmsc::PmscModel& m = *model.pmsc;
  const Eigen::VectorXf* client_full = input.full_values.size() > 0 ? &input.full_values : nullptr;
  pmsc::PartialFullCalculation engine;
  if (input.has_skeleton) {
    engine = [&](const std::vector<int>& points, Eigen::VectorXf& full) {
      PointMatrix posed;
      animation_space::evaluate_vertices(*model.animation_space, input.globals, points, posed);
      full = Eigen::Map<const Eigen::VectorXf>(posed.data(), posed.size());
      return true;
    };
  } else if (!input.lights.empty()) {
    engine = [&](const std::vector<int>& points, Eigen::VectorXf& full) {
      model.illumination->engine->indirect(input.lights, model.illumination->gather, points, full);
      return true;
    };
  }
  pmsc::CachedPose cached;
  pmsc::LocalFailThrough local;
  if (auto covered = pmsc::evaluate_cached_local(m, input.key_values, input.check_values, input.full_points,
                                                 client_full, engine, cached, local);
      !covered.ok()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, "full_points: " + covered.error().message};
  }
  return record_pose(env, model, input, options, cached, cached.points.data(), false, local, out, logged);
}

}  // namespace animspace::server
