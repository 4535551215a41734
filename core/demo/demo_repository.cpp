#include "core/demo/demo_repository.h"

#include <cassert>
#include <string>
#include <system_error>

namespace animspace::demo {

container::ModelContainer make_demo_container(const BendingArmOptions& options, int frames) {
  assert(frames >= 1);
  const ArmRig rig = make_arm_rig(options);
  const std::vector<ArmPose> poses = demo_animation(frames);
  const Eigen::Index n = rig.rest.V.rows();

  container::ModelContainer model;
  auto& metadata = model.metadata();
  metadata["kind"] = "mesh_sequence";
  metadata["description"] =
      "A capped cylinder arm with two bones bending at the elbow, posed by a rig with a biceps "
      "bulge and a volume-keeping elbow (after Merry 2007, sections 2.2.2 and 8.2).";
  metadata["generator"] = "animspace demo bending arm";
  metadata["units"] = "arbitrary (arm length 2)";
  metadata["up_axis"] = "y";

  model.set_points("mesh.rest_points", rig.rest.V);
  model.set_faces("mesh.faces", rig.rest.F);

  container::Int32Matrix parents(kArmBones, 1);
  container::Float64Matrix rest_transforms(kArmBones, 16);
  for (int j = 0; j < kArmBones; ++j) {
    const auto b = static_cast<size_t>(j);
    parents(j, 0) = kArmParents[b];
    // Copied element by element: Eigen::Matrix4d is column-major, the section is row-major.
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) rest_transforms(j, 4 * r + c) = rig.rest_transforms[b](r, c);
    }
  }
  model.set_matrix("skeleton.parents", parents);
  model.set_matrix("skeleton.rest_transforms", rest_transforms);
  model.set_matrix("skinning.weights", FrameMatrix(rig.W.cast<float>()));

  const auto frame_count = static_cast<Eigen::Index>(poses.size());
  FrameMatrix points(frame_count, 3 * n);
  container::Float64Matrix bones(frame_count, 16 * kArmBones);
  container::Float64Matrix parameters(frame_count, 3);
  for (Eigen::Index f = 0; f < frame_count; ++f) {
    const ArmPose& pose = poses[static_cast<size_t>(f)];
    const PointMatrix P = pose_expensive(pose, rig);
    // PointMatrix is row-major, so its storage is already the x0 y0 z0 x1 … row layout.
    points.row(f) = Eigen::Map<const Eigen::RowVectorXf>(P.data(), 3 * n);
    const auto G = bone_transforms(pose, options);
    for (int j = 0; j < kArmBones; ++j) {
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) bones(f, 16 * j + 4 * r + c) = G[static_cast<size_t>(j)](r, c);
      }
    }
    parameters.row(f) << pose.elbow_angle_rad, pose.shoulder_angle_rad, pose.forearm_twist_rad;
  }
  model.set_matrix("sequence.frames", points);
  model.set_matrix("sequence.bone_transforms", bones);
  model.set_matrix("sequence.pose_parameters", parameters);
  return model;
}

std::filesystem::path demo_model_path(const std::filesystem::path& repository) {
  return repository / std::string(kDemoModelName) / std::to_string(kDemoModelVersion) /
         std::string(kDemoModelFileName);
}

Status write_demo_repository(const std::filesystem::path& repository) {
  const std::filesystem::path path = demo_model_path(repository);
  std::error_code error;
  std::filesystem::create_directories(path.parent_path(), error);
  if (error) {
    return make_error(ErrorCode::kIo, "cannot create the demo model directory " +
                                          path.parent_path().string() + ": " + error.message());
  }
  return container::write_file(path, make_demo_container());
}

}  // namespace animspace::demo
