#include "server/pose_evaluation.h"

#include <chrono>

#include <spdlog/spdlog.h>

#include "core/animspace/model.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pmsc_model.h"
#include "server/convert.h"
#include "server/model_lookup.h"
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
    // alone, and the soft cache judges them as it would judge a client's.
    model.illumination->engine->indirect(out.lights, model.illumination->gather, m.key_points, out.key_values);
  } else if (grpc::Status s = decode_points(pose.key_values(), field + ".key_values",
                                            static_cast<uint32_t>(m.key_point_count()),
                                            static_cast<uint32_t>(m.channel_count), "key points", out.key_values);
             !s.ok()) {
    return s;
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

grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, Eigen::VectorXf& out) {
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
  return grpc::Status::OK;
}

grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const std::vector<int>& points,
                                Eigen::VectorXf& out) {
  if (points.empty()) return decode_full_values(model, values, field, key_values, out);
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
  return grpc::Status::OK;
}

grpc::Status evaluate_pose(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                           const PoseOptions& options, v1::PoseResult* out, bool* logged) {
  if (logged != nullptr) *logged = false;
  const pmsc::PmscModel& m = *model.pmsc;
  pmsc::CachedPose cached;
  pmsc::LocalFailThrough local;
  const Eigen::VectorXf* client_full = input.full_values.size() > 0 ? &input.full_values : nullptr;
  const bool local_path = options.local_fail_through || !input.full_points.empty();
  // Server fail-through: the posing engine, posed at the request's skeleton, or the illumination
  // engine, gathering for the request's lights, is the full calculation (decode_pose accepted
  // each input only for a model that has its engine). Locally it computes only the points that
  // need it: animation space is evaluated vertex by vertex (eq. 3.1), and the gather is per point
  // and deterministic, so a point computed alone is the point of the whole frame.
  if (local_path) {
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
    if (auto covered = pmsc::evaluate_cached_local(m, input.key_values, input.full_points, client_full, engine,
                                                   cached, local);
        !covered.ok()) {
      return {grpc::StatusCode::INVALID_ARGUMENT, "full_points: " + covered.error().message};
    }
  } else {
    pmsc::FullCalculation engine;
    if (input.has_skeleton) {
      engine = [&](Eigen::VectorXf& full) {
        PointMatrix posed;
        animation_space::evaluate(*model.animation_space, input.globals, posed);
        full = Eigen::Map<const Eigen::VectorXf>(posed.data(), posed.size());
        return true;
      };
    } else if (!input.lights.empty()) {
      engine = [&](Eigen::VectorXf& full) {
        model.illumination->engine->indirect(input.lights, model.illumination->gather,
                                             model.illumination->engine->all_points(), full);
        return true;
      };
    }
    pmsc::evaluate_cached(m, input.key_values, client_full, engine, cached);
  }

  out->set_status(to_proto(cached.status));
  out->set_key_point_error(static_cast<float>(cached.key_point_error));
  out->set_blend_weight(static_cast<float>(cached.alpha));
  out->set_model_version(model.version);
  out->set_full_evaluation_needed(cached.full_evaluation_needed);
  if (!options.omit_points) {
    if (grpc::Status s = encode_points(cached.points.data(), static_cast<uint32_t>(m.point_count),
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
      // The verdict local fail-through acts on: each region against its own thresholds.
      const auto& thresholds = pmsc::region_thresholds(m, static_cast<int>(r));
      region->set_status(to_proto(pmsc::decide(cached.region_errors[r], thresholds).status));
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

}  // namespace animspace::server
