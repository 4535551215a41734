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

// The linear blend rig of an animation-space model, for a character that any glTF reader skins:
// each influence's weight w_j is its weight p̲_j (the 4th component of p_j), and the bind pose is
// the model's rest pose, v̂ = Σ_j Ĝ_j p_j. Where p_j = w_j Ĝ_j⁻¹ v̂ — a rig imported from linear
// blend skinning (§3.1), its levels of detail before placement — the rig poses exactly as the
// model does; elsewhere (a fitted model, placed LOD vertices) it is the linear blend rig with
// the model's weights and rest pose, equal to it at rest and apart from it by what animation
// space adds over linear blend skinning (§3.2), which the caller measures over its poses.
// Influences of weight 0 (pure tangents of the animation-space position) are dropped. A negative
// weight, which glTF skins cannot hold (§3.2's freedom lets a fitted or placed model have them),
// is dropped too, and the vertex's other weights are rescaled to sum to 1 — still exact at rest —
// and counted, for the caller to report with the deviation it measures.
// Errors: kFailedPrecondition naming the vertex whose weights are all ≤ 0.
struct LinearBlendRig {
  LinearBlendModel model;
  int negative_weights_dropped = 0;
  double most_negative_weight = 0;  // the smallest weight dropped (0 when none)
};
Result<LinearBlendRig> linear_blend_rig(const AnimationSpaceModel& model);

// `poses`: the frames of the animation (G^k per bone, rigid), at `frames_per_second`. Joint names
// are the skeleton's, or "root" and "bone_<j>". Errors: kInvalidArgument naming the pose or bone
// whose transform is not rigid or whose bone count differs.
Result<mesh_io::SkinnedCharacter> skinned_character(const LinearBlendModel& model,
                                                    const std::vector<TransformList>& poses,
                                                    double frames_per_second);

}  // namespace animspace::animation_space
