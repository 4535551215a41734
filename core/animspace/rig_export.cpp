#include "core/animspace/rig_export.h"

#include <string>

#include "core/geometry/normals.h"

namespace animspace::animation_space {

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
