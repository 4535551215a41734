// An articulated model as an engine plays it (issue #51): the linear blend rig its basis holds,
// so that an answer — bone transforms and residual coefficients — poses a skinned mesh with
// morph targets (glTF 2.0 joint matrices and morph weights; animspace export-rig).
//
// The basis's skinning columns hold, per point i and bone j, h_ij = w_ij (p̂_i − c_j, 1)
// (articulated.h). The weights are h_ij's last entry and the offsets d_ij = p̂_i − c_j the rest,
// so a rig with bind positions b_i and bones bound at T(c_j) poses every point as the model
// does. The offsets fix p̂ and c only up to one translation for each set of bones that share
// points; `placement` chooses it.
//
// What an engine cannot reproduce exactly: the residual components are offsets the model adds
// after skinning, in world space, while a glTF morph target is added before skinning and is
// turned by the point's blended bone map. An engine's point is therefore
//   g_i = f̂_i + (Σ_j w_ij A_j − I)(μ_i + Σ_k c_k R_ik)          (A_j: bone j's linear part),
// exact where the blended bone map is the identity (the rest pose, or a pose that only moves
// bones) and off by the residual turned with the limb elsewhere; export-rig measures it over
// the animation it writes (pose_rig against the model's reconstruction). (An exact morph would make the model bilinear in bone transforms and
// coefficients, no longer a subspace whose coordinates the keys determine by least squares.)
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

struct ArticulatedRig {
  Eigen::MatrixX3d bind_points;  // N × 3: p̂_i + μ_i (the rest pose with the residual mean)
  Eigen::MatrixX3d centres;      // B × 3: c_j, bone j bound at the translation T(c_j)
  // Point i's bones bones[offsets[i] … offsets[i + 1]) with weights w_ij > 0, summing to 1
  // (renormalised in double from the basis's float32 weights).
  std::vector<int32_t> offsets, bones;
  std::vector<double> weights;
  std::vector<bool> bone_used;                     // B: false for a bone no point depends on
  std::vector<Eigen::MatrixX3d> residual_targets;  // r components, each N × 3 (R_k)
};

// The rig of an articulated model (subspace_kind articulated, 3 channels, not cross). Each set of
// bones that share points is placed so that its points' centroid is `placement`'s (N × 3, e.g.
// the mesh's rest points) or, without one, at the origin.
// Errors: kFailedPrecondition for another kind of model; kInvalidArgument naming the point and
// bone of a basis not of the skinning form, a negative weight, or a placement of the wrong size.
Result<ArticulatedRig> articulated_rig(const PmscModel& model, const Eigen::MatrixX3d* placement = nullptr);

// An answer's bone j as the world matrix an engine gives its joint node: [R t] · [M_j; 0 0 0 1]
// (R, t the alignment of an aligned model, else the identity), M_j the 3 × 4 of coordinates
// 12j … 12j + 11, row-major. Its joint matrix is that · T(−c_j).
Eigen::Matrix4d bone_world_transform(const PmscModel& model, const Eigen::VectorXd& coordinates,
                                     const geometry::RigidTransform& alignment, int bone);

// Linear blend skinning of the rig at an answer, as an engine computes it: per point
// Σ_j w_ij G_j T(−c_j) [b_i + Σ_k p_k R_ik; 1], in double. N × 3.
Eigen::MatrixX3d pose_rig(const PmscModel& model, const ArticulatedRig& rig, const Eigen::VectorXd& coordinates,
                          const geometry::RigidTransform& alignment);

}  // namespace animspace::pmsc
