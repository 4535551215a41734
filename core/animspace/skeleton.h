// The skeleton of an animation-space model (Merry 2007 §2.1).
//
// Bones are numbered 0 … b-1 and each defines a frame. Bone 0 is the single root; it does not
// undergo character animation, so its frame is model space and G_0 = I (a rigid motion of the
// whole character belongs in the model matrix, §3.1). Every other bone j has a parent φ(j) < j,
// so iterating in index order always visits a parent before its children.
//
// Matrices are 4×4 affine transforms (last row 0 0 0 1), column-vector convention:
//   Ĝ_j    rest transform, bone frame → model space in the rest pose;
//   L_j    joint transform, bone frame → parent frame in some pose;
//   G_j    global transform, G_j = G_φ(j) · L_j, bone frame → model space.
// For a linear-blend-skinned rig, G_j Ĝ_j⁻¹ is the familiar per-bone "skinning matrix".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"

namespace animspace::animation_space {

using Transform = Eigen::Matrix4d;
// One transform per bone, indexed by bone. A pose is the vector of G_j (see global_transforms).
using TransformList = std::vector<Transform, Eigen::aligned_allocator<Transform>>;

struct Skeleton {
  std::vector<int32_t> parents;  // φ(j); parents[0] == -1, 0 <= parents[j] < j otherwise
  TransformList rest;            // Ĝ_j; rest[0] == I
  std::vector<std::string> names;  // optional: empty, or one per bone

  int bone_count() const { return static_cast<int>(parents.size()); }
};

// Checks the invariants above: at least one bone, bone 0 the only root, φ(j) < j, rest
// transforms finite, affine (last row 0 0 0 1) and invertible, Ĝ_0 = I (to 1e-12), names empty
// or one per bone. Errors: kInvalidArgument naming the bone and what was expected.
Status validate(const Skeleton& skeleton);

// A skeleton of just the root: one bone, Ĝ_0 = I.
Skeleton root_only_skeleton();

// L̂_j = Ĝ_φ(j)⁻¹ Ĝ_j, the joint transforms of the rest pose (L̂_0 = I).
TransformList rest_joint_transforms(const Skeleton& skeleton);

// G_j = G_φ(j) L_j with G_0 = L_0 (normally I). `joints` has one transform per bone.
TransformList global_transforms(const Skeleton& skeleton, const TransformList& joints);

// L_j = G_φ(j)⁻¹ G_j, the inverse of global_transforms.
TransformList joint_transforms(const Skeleton& skeleton, const TransformList& globals);

// Checks that `globals` is a usable pose for `skeleton`: one finite affine transform per bone.
// Errors: kInvalidArgument naming `what`, the bone and the problem (count, non-finite, last row).
Status validate_pose(const Skeleton& skeleton, const TransformList& globals, const std::string& what);

// Inverse of an affine transform, exploiting the last row (cheaper and better conditioned than a
// general 4×4 inverse).
Transform affine_inverse(const Transform& transform);

// A rigid transform: rotation R (3×3, orthonormal) then translation t.
Transform make_transform(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation);

// `count` random poses: every non-root joint turned, in its rest frame about its origin, by an
// angle uniform in [−max_angle, max_angle] (radians) about a uniformly random axis; translations
// stay the rest ones (§3.3.1's "rotations, fixed translations"). Deterministic for a seed. How
// P = E[GᵀG] is estimated for a rig that comes without example poses.
std::vector<TransformList> random_joint_rotation_poses(const Skeleton& skeleton, int count, double max_angle,
                                                       uint64_t seed);

}  // namespace animspace::animation_space
