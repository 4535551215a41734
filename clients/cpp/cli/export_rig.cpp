#include "clients/cpp/cli/export_rig.h"

#include <algorithm>
#include <cmath>
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
#include "core/pmsc/articulated_rig.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/subspace.h"

namespace animspace::cli {

namespace as = animation_space;

namespace {

// An articulated pmsc model (issue #51) as a glTF skinned mesh with morph targets: the rig its
// basis holds (pmsc/articulated_rig.h), one affine joint per bone, one morph target per residual
// component, and as the animation the answers the model gives its own training frames from their
// key points — the joint matrices and morph weights of each answer, exactly what a client sets
// in an engine. Prints how far that glTF plays from the model's answers (the residual turned with
// the bones, articulated_rig.h).
int export_articulated(const container::ModelContainer& in, const ExportRigArgs& a, bool json) {
  const char* command = "export-rig";
  if (a.level != 0) {
    return fail(command, "--level: a pmsc model has one level of detail (0), got " + std::to_string(a.level));
  }
  auto loaded = pmsc::load(in, a.input);
  if (!loaded) return fail(command, loaded.error().message);
  const auto model = std::make_shared<const pmsc::PmscModel>(std::move(*loaded));
  const long N = model->point_count;
  Eigen::MatrixX3d placement;
  if (in.has_section(container::sections::kRestPoints)) {
    auto rest = in.points(container::sections::kRestPoints);
    if (!rest) return fail(command, rest.error().message);
    if (rest->rows() == N) placement = rest->cast<double>();
  }
  if (!in.has_section(container::sections::kFaces)) {
    return fail(command, a.input + " has no faces (section mesh.faces): a glTF mesh is made of triangles");
  }
  auto faces = in.faces(container::sections::kFaces);
  if (!faces) return fail(command, faces.error().message);
  auto subspace = pmsc::make_subspace(model);
  if (!subspace) return fail(command, a.input + ": " + subspace.error().message);

  // The animation: each stored training frame answered from its key points, as a server answers.
  FrameMatrix frames;
  if (in.has_section(container::sections::kSequenceFrames)) {
    auto stored = in.float_matrix(container::sections::kSequenceFrames, static_cast<int>(3 * N));
    if (!stored) return fail(command, stored.error().message);
    frames = std::move(*stored);
  }
  const long K = static_cast<long>(model->key_points.size());
  std::vector<pmsc::PoseEstimate> answers(static_cast<size_t>(frames.rows()));
  Eigen::VectorXf key_values(3 * K);
  for (Eigen::Index f = 0; f < frames.rows(); ++f) {
    for (long k = 0; k < K; ++k) {
      key_values.segment<3>(3 * k) = frames.row(f).segment<3>(3 * model->key_points[static_cast<size_t>(k)]).transpose();
    }
    (*subspace)->estimate(key_values, Eigen::VectorXf(), answers[static_cast<size_t>(f)]);
  }
  // The rig, its morph targets fitted to those answers with a ridge chosen on the last 40% of
  // them (pmsc/articulated_rig.h), and how far each rig plays from the model's points.
  pmsc::RigFit fit;
  auto rig = pmsc::fit_articulated_rig(*model, placement.rows() == N ? &placement : nullptr, answers, fit);
  if (!rig) return fail(command, a.input + ": " + rig.error().message);
  double diagonal = 0;
  for (const pmsc::PoseEstimate& estimate : answers) {
    Eigen::VectorXf points(3 * N);
    const pmsc::PoseEstimate* one[] = {&estimate};
    float* destination[] = {points.data()};
    (*subspace)->reconstruct(one, destination);
    const auto xyz = Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>>(points.data(), N, 3);
    diagonal = std::max(diagonal, static_cast<double>((xyz.colwise().maxCoeff() - xyz.colwise().minCoeff()).norm()));
  }
  const auto percent = [&](double distance) { return diagonal > 0 ? 100 * distance / diagonal : 0.0; };

  // The joints: the bones some point depends on, in order.
  std::vector<int32_t> joint_of(static_cast<size_t>(model->bone_count), -1);
  std::vector<int> bones;
  for (int j = 0; j < model->bone_count; ++j) {
    if (!rig->bone_used[static_cast<size_t>(j)]) continue;
    joint_of[static_cast<size_t>(j)] = static_cast<int32_t>(bones.size());
    bones.push_back(j);
  }
  mesh_io::SkinnedCharacter character;
  character.name = model_name_of(a.input);
  character.animation_name = "training frames";
  character.frames_per_second = a.frames_per_second;
  character.affine_joints = true;
  character.bind_points = rig->bind_points;
  character.faces = *faces;
  character.offsets = rig->offsets;
  character.weights = rig->weights;
  for (const int32_t bone : rig->bones) character.joints.push_back(joint_of[static_cast<size_t>(bone)]);
  for (const int j : bones) {
    character.joint_parents.push_back(-1);
    character.joint_names.push_back("bone_" + std::to_string(j));
    Eigen::Matrix4d bind = Eigen::Matrix4d::Identity();
    bind.topRightCorner<3, 1>() = rig->centres.row(j).transpose();
    character.bind_globals.push_back(bind);
  }
  character.morph_targets = rig->residual_targets;
  for (size_t k = 0; k < rig->residual_targets.size(); ++k) {
    character.morph_target_names.push_back("residual_" + std::to_string(k));
  }
  character.frame_morph_weights.resize(frames.rows(), model->residual_components);
  for (size_t f = 0; f < answers.size(); ++f) {
    mesh_io::Matrix4dList globals;
    for (const int j : bones) {
      globals.push_back(pmsc::bone_world_transform(*model, answers[f].coordinates, answers[f].alignment, j));
    }
    character.frame_globals.push_back(std::move(globals));
    character.frame_morph_weights.row(static_cast<Eigen::Index>(f)) =
        answers[f].coordinates.tail(model->residual_components).transpose();
  }
  if (auto written = mesh_io::write_skinned_character(a.output, character); !written.ok()) {
    return fail(command, written.error().message);
  }
  if (json) {
    print_json({{"output", a.output},
                {"subspace_kind", "articulated"},
                {"vertices", N},
                {"joints", bones.size()},
                {"morph_targets", model->residual_components},
                {"frames", frames.rows()},
                {"max_deviation", fit.max_deviation},
                {"max_deviation_over_diagonal", diagonal > 0 ? fit.max_deviation / diagonal : 0.0},
                {"unfitted_max_deviation", fit.plain_max_deviation},
                {"morph_ridge", std::isfinite(fit.ridge) ? nlohmann::json(fit.ridge) : nlohmann::json(nullptr)},
                {"held_out_frames", fit.held_out},
                {"held_out_max_deviation", fit.held_out_max_deviation},
                {"held_out_unfitted_max_deviation", fit.held_out_plain_max_deviation}});
  } else {
    std::printf("articulated model: %ld points, %zu bones as affine joints, %d residual components as morph "
                "targets, %lld training frames answered from their %ld key points\n",
                N, bones.size(), model->residual_components, static_cast<long long>(frames.rows()), K);
    // glTF adds a morph target before skinning, the model its residual after: the targets are
    // fitted to the answers, so each figure says how far an engine's point is from the model's.
    if (std::isfinite(fit.ridge)) {
      std::printf("morph targets fitted to the answers (glTF morphs before skinning, the model adds its residual "
                  "after), ridge %.3g chosen on the last %ld frames: within %.4g of the model's points there "
                  "(%.3g%% of the diagonal), against %.4g (%.3g%%) with the residual components as they are\n",
                  fit.ridge, fit.held_out, fit.held_out_max_deviation, percent(fit.held_out_max_deviation),
                  fit.held_out_plain_max_deviation, percent(fit.held_out_plain_max_deviation));
    } else if (fit.held_out > 0) {
      std::printf("morph targets are the residual components as they are: no fit to the answers did better on the "
                  "last %ld frames (%.4g, %.3g%% of the diagonal)\n",
                  fit.held_out, fit.held_out_plain_max_deviation, percent(fit.held_out_plain_max_deviation));
    }
    std::printf("the glTF plays every answer within %.4g of the model's points (%.3g%% of the diagonal)\nwrote %s\n",
                fit.max_deviation, percent(fit.max_deviation), a.output.c_str());
  }
  return 0;
}

}  // namespace

CLI::App* add_export_rig(CLI::App& app, ExportRigArgs& a) {
  auto* cmd = app.add_subcommand(
      "export-rig",
      "Offline: write an animation-space model (fitted, import-rig, subdivided, or a level of detail of build-lod) "
      "as a glTF 2.0 skinned character: its linear blend rig (weights p̲_j, bind pose the rest pose), the stored "
      "training poses as its animation, the atlas's UVs at the level (TEXCOORD_0, seams split; a coarser level's as "
      "build-lod stored them under the atlas); prints how far the rig is "
      "from the model over those poses. An articulated pmsc model (train-pmsc --subspace articulated) is written as "
      "its skinning's affine bones plus its residual components as morph targets, animated by its answers to its "
      "own training frames");
  cmd->add_option("input", a.input, "An animation-space model.anim, or an articulated pmsc model")->required()->check(CLI::ExistingFile);
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
  if (in->metadata_value("kind") == container::kind_name(container::ModelKind::kPmsc)) {
    return export_articulated(*in, a, json);
  }
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
