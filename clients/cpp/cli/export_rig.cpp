#include "clients/cpp/cli/export_rig.h"

#include <algorithm>
#include <cstdio>
#include <vector>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/number_checks.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/rig_export.h"
#include "core/atlas/atlas_io.h"
#include "core/container/sections.h"
#include "core/lod/lod_io.h"
#include "core/mesh_io/gltf_skin_writer.h"

namespace animspace::cli {

namespace as = animation_space;

CLI::App* add_export_rig(CLI::App& app, ExportRigArgs& a) {
  auto* cmd = app.add_subcommand(
      "export-rig",
      "Offline: write an animation-space model (fitted, import-rig, subdivided, or a level of detail of build-lod) "
      "as a glTF 2.0 skinned character: its linear blend rig (weights p̲_j, bind pose the rest pose), the stored "
      "training poses as its animation, the atlas's UVs at the level (TEXCOORD_0, seams split; a coarser level's as "
      "build-lod stored them under the atlas); prints how far the rig is "
      "from the model over those poses");
  cmd->add_option("input", a.input, "An animation-space model.anim")->required()->check(CLI::ExistingFile);
  cmd->add_option("--level", a.level, "Level of detail to write (0 = full detail)")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  cmd->add_option("--fps", a.frames_per_second, "Frames per second of the animation")
      ->check(tools::kPositive)
      ->capture_default_str();
  cmd->add_option("-o,--output", a.output, "Output: .glb or .gltf")->required();
  return cmd;
}

int run_export_rig(const ExportRigArgs& a, bool json) {
  const char* command = "export-rig";
  if (const std::string bad = check_output_extension(a.output, {".glb", ".gltf"}, "export-rig writes glTF");
      !bad.empty()) {
    return fail(command, bad);
  }
  auto in = container::read_file(a.input);
  if (!in) return fail(command, in.error().message);
  auto model = as::load(*in, a.input);
  if (!model) return fail(command, model.error().message);
  auto levels = lod::load_levels(*in, *model, a.input);
  if (!levels) return fail(command, levels.error().message);
  if (a.level >= levels->count()) {
    return fail(command, "--level: expected 0 … " + std::to_string(levels->count() - 1) + " (" + a.input + " has " +
                             std::to_string(levels->count()) + " levels), got " + std::to_string(a.level));
  }
  const as::AnimationSpaceModel& level = levels->levels[static_cast<size_t>(a.level)].model;
  auto converted = as::linear_blend_rig(level);
  if (!converted) return fail(command, a.input + ": " + converted.error().message);
  const as::LinearBlendModel* rig = &converted->model;

  // The animation: the model's stored training poses, or its rest pose alone.
  std::vector<as::TransformList> poses;
  if (in->has_section(container::sections::kSequenceBoneTransforms)) {
    auto rows = in->double_matrix(container::sections::kSequenceBoneTransforms, 16 * model->bone_count());
    if (!rows) return fail(command, rows.error().message);
    for (Eigen::Index k = 0; k < rows->rows(); ++k) poses.push_back(as::pose_from_row(*rows, k, model->bone_count()));
  }
  if (poses.empty()) poses.push_back(model->skeleton.rest);

  // How far the rig poses from the model (0 to rounding for a rig imported from linear blend
  // skinning): the largest distance of any vertex over the animation and 50 random poses — every
  // joint turned up to 30° (a model stored without poses has only its rest pose, where the rig is
  // exact by construction) — and over the diagonal.
  constexpr int kRandomPoses = 50;
  constexpr double kMaxJointAngle = 30 * 3.14159265358979323846 / 180;
  std::vector<as::TransformList> measured = poses;
  for (auto& pose : as::random_joint_rotation_poses(model->skeleton, kRandomPoses, kMaxJointAngle, 1)) {
    measured.push_back(std::move(pose));
  }
  PointMatrix from_model, from_rig;
  double deviation = 0;
  for (const auto& pose : measured) {
    as::evaluate(level, pose, from_model);
    as::evaluate(*rig, pose, from_rig);
    deviation = std::max(deviation, static_cast<double>((from_model - from_rig).rowwise().norm().maxCoeff()));
  }
  as::evaluate(level, model->skeleton.rest, from_model);
  const double diagonal =
      (from_model.colwise().maxCoeff() - from_model.colwise().minCoeff()).cast<double>().norm();

  auto character = as::skinned_character(*rig, poses, a.frames_per_second);
  if (!character) return fail(command, character.error().message);
  character->name = model_name_of(a.input);
  // The atlas (animspace atlas): level 0 carries its UVs, a coarser level those build-lod stored
  // with it (lod/chart_atlas.h); the vertices split along its seams with their joints and weights.
  bool with_uvs = false;
  auto stored = atlas::load_atlas(*in, model->faces.rows(), a.input);
  if (!stored) return fail(command, stored.error().message);
  const lod::CornerUvs& level_uvs = levels->levels[static_cast<size_t>(a.level)].corner_uvs;
  const lod::CornerUvs* uvs = !*stored ? nullptr : a.level == 0 ? &(*stored)->uvs
                                                 : level_uvs.rows() > 0 ? &level_uvs
                                                                        : nullptr;
  if (uvs != nullptr) {
    *character = mesh_io::split_seams(*character, uvs->cast<float>());
    with_uvs = true;
  }
  if (auto written = mesh_io::write_skinned_character(a.output, *character); !written.ok()) {
    return fail(command, written.error().message);
  }
  if (json) {
    print_json({{"output", a.output},
                {"level", a.level},
                {"vertices", rig->vertex_count()},
                {"joints", rig->skeleton.bone_count()},
                {"influences", rig->influences.influence_count()},
                {"frames", poses.size()},
                {"negative_weights_dropped", converted->negative_weights_dropped},
                {"most_negative_weight", converted->most_negative_weight},
                {"max_deviation", deviation},
                {"max_deviation_over_diagonal", diagonal > 0 ? deviation / diagonal : 0.0},
                {"texture_coordinates", with_uvs},
                {"written_vertices", character->bind_points.rows()}});
  } else {
    std::printf("level %d: %d vertices, %d joints, %.2f influences per vertex, %zu frames\n", a.level,
                rig->vertex_count(), rig->skeleton.bone_count(),
                static_cast<double>(rig->influences.influence_count()) / std::max(rig->vertex_count(), 1), poses.size());
    if (converted->negative_weights_dropped > 0) {
      std::printf("%d negative weights (down to %.3g), which a glTF skin cannot hold, dropped and their vertices' "
                  "other weights rescaled\n",
                  converted->negative_weights_dropped, converted->most_negative_weight);
    }
    if (with_uvs) {
      std::printf("with the atlas's texture coordinates: %lld vertices once split along its seams\n",
                  static_cast<long long>(character->bind_points.rows()));
    }
    std::printf("the linear blend rig poses within %.4g of the model (%.3g%% of the diagonal) over %zu poses: the "
                "animation and %d random ones, joints turned up to 30°\nwrote %s\n",
                deviation, diagonal > 0 ? 100 * deviation / diagonal : 0.0, measured.size(), kRandomPoses,
                a.output.c_str());
  }
  return 0;
}

}  // namespace animspace::cli
