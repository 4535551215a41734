#include "core/animspace/rig_export.h"

#include <algorithm>
#include <string>

#include "core/geometry/normals.h"

namespace animspace::animation_space {

Result<LinearBlendRig> linear_blend_rig(const AnimationSpaceModel& model) {
  LinearBlendRig out;
  LinearBlendModel& rig = out.model;
  rig.skeleton = model.skeleton;
  rig.faces = model.faces;
  const int vertices = model.vertex_count();
  rig.rest_points.resize(3, vertices);
  std::vector<double> weights;
  for (int i = 0; i < vertices; ++i) {
    Eigen::Vector3d rest = Eigen::Vector3d::Zero();
    const size_t first = weights.size();
    double kept = 0;
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      const int bone = model.influences.bones[static_cast<size_t>(k)];
      const Eigen::Vector4d p = model.positions.col(k);
      rest += (model.skeleton.rest[static_cast<size_t>(bone)] * p).head<3>();
      if (p(3) < 0) {
        ++out.negative_weights_dropped;
        out.most_negative_weight = std::min(out.most_negative_weight, p(3));
      }
      if (p(3) <= 0) continue;
      rig.influences.bones.push_back(bone);
      weights.push_back(p(3));
      kept += p(3);
    }
    if (weights.size() == first) {
      return make_error(ErrorCode::kFailedPrecondition,
                        "vertex " + std::to_string(i) + ": no bone has a positive weight, so no linear blend (glTF) "
                                                        "skin can carry it");
    }
    for (size_t k = first; k < weights.size(); ++k) weights[k] /= kept;
    rig.influences.offsets.push_back(static_cast<int32_t>(rig.influences.bones.size()));
    rig.rest_points.col(i) = rest;
  }
  rig.weights = Eigen::Map<const Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  ANIMSPACE_RETURN_IF_ERROR(validate(rig));
  return out;
}

Result<mesh_io::SkinnedCharacter> skinned_character(const LinearBlendModel& model,
                                                    const std::vector<TransformList>& poses,
                                                    double frames_per_second) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  const int bones = model.skeleton.bone_count();
  mesh_io::SkinnedCharacter character;
  character.bind_points = model.rest_points.transpose();
  character.faces = model.faces;
  if (model.faces.rows() > 0) character.normals = geometry::area_weighted_normals(character.bind_points, model.faces);
  character.joint_parents = model.skeleton.parents;
  for (int j = 0; j < bones; ++j) {
    character.joint_names.push_back(!model.skeleton.names.empty() ? model.skeleton.names[static_cast<size_t>(j)]
                                    : j == 0                      ? std::string("root")
                                                                  : "bone_" + std::to_string(j));
  }
  character.bind_globals.assign(model.skeleton.rest.begin(), model.skeleton.rest.end());
  character.offsets = model.influences.offsets;
  character.joints = model.influences.bones;
  character.weights.assign(model.weights.data(), model.weights.data() + model.weights.size());
  for (size_t k = 0; k < poses.size(); ++k) {
    if (static_cast<int>(poses[k].size()) != bones) {
      return make_error(ErrorCode::kInvalidArgument, "skinned_character: poses[" + std::to_string(k) + "] has " +
                                                         std::to_string(poses[k].size()) + " bones, expected " +
                                                         std::to_string(bones));
    }
    character.frame_globals.emplace_back(poses[k].begin(), poses[k].end());
  }
  character.frames_per_second = frames_per_second;
  return character;
}

}  // namespace animspace::animation_space
