// Rigid bone motions for a fixed skinning: the transform half of skinning decomposition (SSDR,
// Le & Deng 2012 §4.2) and the way a pose that was not fitted is recovered (Dem Bones' "solve
// transformations with the weights fixed").
//
// Both linear blend skinning and animation space pose a vertex by a sum over its influences of a
// bone transform applied to a 4-vector. Written with the rigid motion M_j = G_j Ĝ_j⁻¹ (bone j's
// rest pose → this pose) instead of G_j, every influence carries y_ij = Ĝ_j p_ij (Merry 2007
// eq. 3.1 with the rest transform moved into the vector):
//   v_i = Σ_j M_j y_ij = Σ_j (R_j x_ij + w_ij t_j),     y_ij = (x_ij, w_ij),
// with x_ij = w_ij v̂_i for linear blend skinning (§3.1: p_j = w_j Ĝ_j⁻¹ v̂). One solver therefore
// serves both models.
//
// With every other bone fixed, the best rigid M_j for one frame minimises
//   Σ_i ‖R x_i + w_i t − q_i‖²,      q_i = v_i − Σ_{l≠j} M_l y_il,
// over the vertices bone j influences. For fixed R the best t is q̄ − R x̄ with
// x̄ = Σ w_i x_i / Σ w_i², q̄ = Σ w_i q_i / Σ w_i²; substituting it leaves an orthogonal Procrustes
// problem between x_i − w_i x̄ and q_i − w_i q̄ (the cross terms vanish because
// Σ w_i (x_i − w_i x̄) = 0), solved by the SVD of H = Σ (q_i − w_i q̄)(x_i − w_i x̄)ᵀ with the
// reflection fixed (Umeyama 1991). For linear blend skinning this is SSDR's weighted Procrustes
// (points weighted w_i², targets q_i / w_i). Cycling over the bones is block coordinate descent:
// the squared error never increases.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"

namespace animspace::animation_space {

// A skinning posed by rest-to-pose motions: influence k of vertex i is bone influences.bones[k]
// with the 4-vector y.col(k) (see the file comment).
struct MotionSkinning {
  InfluenceSets influences;
  InfluenceVectors y;  // 4 × I
  int vertex_count() const { return influences.vertex_count(); }
};

// y_ij = Ĝ_j p_ij.
MotionSkinning motion_skinning(const AnimationSpaceModel& model);
// y_ij = w_ij (v̂_i, 1).
MotionSkinning motion_skinning(const LinearBlendModel& model);

// The rigid motion minimising Σ_i ‖R x_i + w_i t − q_i‖² (x, q: 3 × n; w: n), det R = +1. When
// Σ w_i² is 0 the translation is not determined and `fallback`'s is kept (its rotation too when H
// vanishes as well).
Transform fit_bone_motion(const Eigen::Matrix3Xd& x, const Eigen::VectorXd& w, const Eigen::Matrix3Xd& q,
                          const Transform& fallback = Transform::Identity());

// Which influences each bone has: for bone j, the influence indices k (ascending) with
// influences.bones[k] == j, and the vertex of each.
struct BoneInfluences {
  std::vector<int32_t> offsets;   // bone_count + 1
  std::vector<int32_t> influence;  // I: influence index k
  std::vector<int32_t> vertex;     // I: vertex of influence k
};
BoneInfluences bone_influences(const InfluenceSets& influences, int bone_count);

// v_i = Σ_j M_j y_ij for every vertex; `out` becomes 3 × V.
void pose_with_motions(const MotionSkinning& skinning, const TransformList& motions, Eigen::Matrix3Xd& out);

// `sweeps` rounds of block coordinate descent over the bones (index order) for one frame
// (3 × V): each bone's motion is replaced by its best rigid motion with the others fixed. Bones
// listed in `fixed` (e.g. the root, which stays I) are not changed. Returns the sum of squared
// vertex errors after the last sweep.
double refine_motions(const MotionSkinning& skinning, const BoneInfluences& by_bone, const Eigen::Matrix3Xd& frame,
                      TransformList& motions, int sweeps, const std::vector<int32_t>& fixed = {0});

struct MotionSolveOptions {
  int max_sweeps = 100;
  // Stop when a sweep lowers the squared error by less than this fraction of it.
  double tolerance = 1e-6;
};

// The motions of a frame the skinning was not fitted to (3 × V), with the skinning fixed: each
// bone starts at the rigid fit of the rest positions v̂_i = Σ_j y_ij to the frame over its
// influences (weighted by w_ij², so vertices it hardly moves barely count), then sweeps of
// refine_motions until they settle. Bone 0 stays I. Returns M_j per bone.
TransformList solve_motions(const MotionSkinning& skinning, const BoneInfluences& by_bone,
                            const Eigen::Matrix3Xd& frame, const MotionSolveOptions& options = {});

// The same as a pose of `model`: G_j = M_j Ĝ_j for a frame of 3V values x0 y0 z0 x1 … .
TransformList solve_pose(const AnimationSpaceModel& model, const Eigen::Ref<const Eigen::RowVectorXf>& frame,
                         const MotionSolveOptions& options = {});
TransformList solve_pose(const LinearBlendModel& model, const Eigen::Ref<const Eigen::RowVectorXf>& frame,
                         const MotionSolveOptions& options = {});

// A frame row (3V values) as 3 × V doubles.
Eigen::Matrix3Xd frame_points(const Eigen::Ref<const Eigen::RowVectorXf>& frame);

}  // namespace animspace::animation_space
