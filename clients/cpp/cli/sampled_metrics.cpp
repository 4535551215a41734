#include "clients/cpp/cli/sampled_metrics.h"

#include <numbers>

namespace animspace::cli {

namespace as = animation_space;

void add_sample_pose_options(CLI::App* cmd, SamplePoseArgs& a) {
  cmd->add_option("--sample-poses", a.sample_poses,
                  "For a model without stored metrics: estimate P = E[GᵀG] from this many random poses")
      ->check(CLI::Range(0, 100000));
  cmd->add_option("--max-joint-angle", a.max_joint_angle_degrees, "Random poses: largest joint rotation, degrees")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  cmd->add_option("--seed", a.seed, "Random poses: seed")->capture_default_str();
}

Result<as::StoredMetrics> model_metrics(const container::ModelContainer& in, const as::AnimationSpaceModel& model,
                                        const SamplePoseArgs& a, const std::string& source,
                                        container::ModelContainer& out, const std::string& alternative) {
  if (a.sample_poses > 0) {
    auto sampled = as::stored_metrics_from_poses(
        model, as::random_joint_rotation_poses(model.skeleton, a.sample_poses,
                                               a.max_joint_angle_degrees * std::numbers::pi / 180, a.seed));
    if (!sampled) return make_error(sampled.error().code, "--sample-poses: " + sampled.error().message);
    as::store_metrics(*sampled, out);
    out.metadata()["animspace.metrics"] = "sampled: " + std::to_string(a.sample_poses) + " random poses up to " +
                                          std::to_string(a.max_joint_angle_degrees) + " degrees per joint";
    return sampled;
  }
  auto loaded = as::load_metrics(in, model.bone_count(), source);
  if (!loaded) {
    return make_error(loaded.error().code,
                      loaded.error().message + "; give --sample-poses N to estimate them from random poses" +
                          (alternative.empty() ? "" : ", or " + alternative));
  }
  return loaded;
}

}  // namespace animspace::cli
