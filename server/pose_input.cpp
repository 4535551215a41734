#include "server/pose_input.h"

#include "core/pmsc/pmsc_model.h"
#include "server/convert.h"
#include "server/model_lookup.h"
#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

// Why a pose may not carry an engine input this model's engine does not take.
std::string engine_note(const LoadedModel& model) {
  if (model.pmsc->cross) return "is impossible";
  if (model.engine) return std::string("takes ") + std::string(model::input_name(model.engine->input()));
  return "is by the client: send full values with CompleteMiss";
}

// INVALID_ARGUMENT for an engine input `input` the model's engine does not take.
grpc::Status refuse_engine_input(const LoadedModel& model, const std::string& field, model::Engine::Input input,
                                 std::string_view engine) {
  const std::string name(model::input_name(input));
  return invalid_argument(field + "." + name + ": model '" + model.name + "' has no " + std::string(engine) +
                          " on the server (fail-through " + engine_note(model) + "); leave " + name + " unset");
}

bool takes(const LoadedModel& model, model::Engine::Input input) {
  return model.engine && model.engine->input() == input;
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
  using Input = model::Engine::Input;
  const pmsc::PmscModel& m = *model.pmsc;
  if (pose.has_light_set()) {
    if (!takes(model, Input::kLightSet)) {
      return refuse_engine_input(model, field, Input::kLightSet, "illumination engine");
    }
    if (grpc::Status s = decode_light_set(pose.light_set(), field + ".light_set",
                                          model.illumination->default_intensity(), out.lights);
        !s.ok()) {
      return s;
    }
    out.has_engine_input = true;
  }
  if (out.has_engine_input && !pose.has_key_values()) {
    // The server is the renderer here (Meyer & Anderson 2007 §3.2): its engine computes the key
    // points and the check points alone, and the soft cache judges them as it would a client's.
    if (pose.has_check_values()) {
      return invalid_argument(field + ".check_values: sent without key_values; the server gathers both for the "
                                      "light_set (send both, or neither)");
    }
    model.engine->points(out, m.key_points, out.key_values);
    if (m.check_point_count() > 0) model.engine->points(out, m.check_points, out.check_values);
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
  if (!pose.has_skeleton_pose()) return grpc::Status::OK;
  if (!takes(model, Input::kSkeletonPose)) {
    return refuse_engine_input(model, field, Input::kSkeletonPose, "posing engine");
  }
  out.has_engine_input = true;
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
  return decode_full_values(model, values, field, key_values, check_values, {}, out);
}

grpc::Status decode_full_values(const LoadedModel& model, const v1::PointArray& values, const std::string& field,
                                const Eigen::VectorXf& key_values, const Eigen::VectorXf& check_values,
                                const std::vector<int>& points, Eigen::VectorXf& out) {
  const pmsc::PmscModel& m = *model.pmsc;
  const bool whole = points.empty();
  if (grpc::Status s = decode_points(values, field,
                                     static_cast<uint32_t>(whole ? m.point_count : static_cast<int>(points.size())),
                                     static_cast<uint32_t>(m.channel_count),
                                     whole ? "points" : "points (one per full_points entry)", out);
      !s.ok()) {
    return s;
  }
  // A cross model's key points are another point set: nothing in the output repeats them.
  if (m.cross) return grpc::Status::OK;
  const Status at_keys = whole ? pmsc::check_full_values_at_keys(m, key_values, out)
                               : pmsc::check_full_values_at_keys(m, key_values, points, out);
  if (!at_keys.ok()) return to_grpc_status(at_keys.error(), field);
  const Status at_checks = whole ? pmsc::check_full_values_at_checks(m, check_values, out)
                                 : pmsc::check_full_values_at_checks(m, check_values, points, out);
  if (!at_checks.ok()) return to_grpc_status(at_checks.error(), field);
  return grpc::Status::OK;
}

}  // namespace animspace::server
