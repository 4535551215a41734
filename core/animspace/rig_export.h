// A fitted linear blend rig as a character a DCC tool or game engine plays: glTF 2.0's skinned
// mesh (Khronos glTF 2.0 §3.7.3 Skins) with the fitted sequence as its animation (§3.11).
//
// The skeleton maps one to one: joint j is bone j (bone 0, the fixed super-root, is the root
// joint; no vertex is weighted to it), the bind pose is the rest pose, each joint's global bind
// transform is Ĝ_j (so glTF's inverse bind matrix is Ĝ_j⁻¹ and its joint matrix G_j Ĝ_j⁻¹, the
// skinning matrix of eq. 2.2), and frame k's joint globals are the fitted G^k_j. glTF poses a
// vertex by Σ_j w_j G_j Ĝ_j⁻¹ v̂: exactly the linear blend model's evaluate.
#pragma once

#include <vector>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/mesh_io/gltf_skin_writer.h"

namespace animspace::animation_space {

// `poses`: the frames of the animation (G^k per bone, rigid), at `frames_per_second`. Joint names
// are the skeleton's, or "root" and "bone_<j>". Errors: kInvalidArgument naming the pose or bone
// whose transform is not rigid or whose bone count differs.
Result<mesh_io::SkinnedCharacter> skinned_character(const LinearBlendModel& model,
                                                    const std::vector<TransformList>& poses,
                                                    double frames_per_second);

}  // namespace animspace::animation_space
