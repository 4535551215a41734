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
// bones) and off by the residual turned with the limb elsewhere. (An exact morph would make the
// model bilinear in bone transforms and coefficients, no longer a subspace whose coordinates the
// keys determine by least squares.) Given poses, the rig's morph targets are instead fitted to
// them: per point, the bind offset μ'_i and targets d_ik that minimise
//   Σ_poses ‖B_i (μ'_i + Σ_k p_k d_ik) − (μ_i + Σ_k p_k R_ik)‖²,   B_i = Σ_j w_ij A_j,
// the best constant morphs for those answers in least squares (3(r + 1) unknowns a point), with
// a ridge λ (a fraction of the normal matrix's mean diagonal) toward μ and R: λ → ∞ is the plain
// rig. With r ≈ 40 a point has 120 unknowns, as many as the equations of 40 answers, so λ is
// chosen by rule on answers the fit does not see (fit_articulated_rig): fitted to the first 60%
// of the answers, the λ of kTargetRidges (or the plain rig) whose worst point on the rest is
// nearest the model's f̂. On crane's first 105 frames an unregularised fit is 0.19% of the
// diagonal from the answers it saw but 3.0% on the rest, where the plain rig is 1.3%.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

struct ArticulatedRig {
  Eigen::MatrixX3d bind_points;  // N × 3: p̂_i + μ_i (the rest pose with the residual mean), or p̂_i + μ'_i
  Eigen::MatrixX3d centres;      // B × 3: c_j, bone j bound at the translation T(c_j)
  // Point i's bones bones[offsets[i] … offsets[i + 1]) with weights w_ij > 0, summing to 1
  // (renormalised in double from the basis's float32 weights).
  std::vector<int32_t> offsets, bones;
  std::vector<double> weights;
  std::vector<bool> bone_used;                     // B: false for a bone no point depends on
  std::vector<Eigen::MatrixX3d> residual_targets;  // r components, each N × 3 (R_k, or the fitted d_k)
};

inline constexpr double kTargetRidges[] = {1e-4, 1e-3, 1e-2, 1e-1, 1, 10};
// The share of the answers the ridge is chosen on (the first ones: the rest is a new shot to them).
inline constexpr double kTargetFitShare = 0.6;

// The rig of an articulated model (subspace_kind articulated, 3 channels, not cross). Each set of
// bones that share points is placed so that its points' centroid is `placement`'s (N × 3, e.g.
// the mesh's rest points) or, without one, at the origin. Without `fit_to` the bind pose is
// p̂ + μ and the targets are the residual components R; with it (answers' coordinates, each M
// values) both are fitted to those answers, above.
// Errors: kFailedPrecondition for another kind of model; kInvalidArgument naming the point and
// bone of a basis not of the skinning form, a negative weight, or a placement of the wrong size.
Result<ArticulatedRig> articulated_rig(const PmscModel& model, const Eigen::MatrixX3d* placement = nullptr,
                                       const std::vector<Eigen::VectorXd>* fit_to = nullptr, double ridge = 1e-6);

// What fit_articulated_rig chose and measured: worst point distance from the model's f̂ (model
// units) of the rig it returns, over all the answers, and on the held-out answers (the last 40%)
// of the rig fitted at the chosen λ to the first 60%, against the plain rig's on both.
struct RigFit {
  double ridge = 0;    // the chosen λ; +inf: the plain rig (no fit did better on the held-out answers)
  long held_out = 0;   // answers the choice was measured on
  double max_deviation = 0, plain_max_deviation = 0;
  double held_out_max_deviation = 0, held_out_plain_max_deviation = 0;
};
// The rig with its morph targets fitted to `answers` (coordinates and alignment of each; at
// least 5 for a choice, else the plain rig), λ chosen as above, and the report.
Result<ArticulatedRig> fit_articulated_rig(const PmscModel& model, const Eigen::MatrixX3d* placement,
                                           const std::vector<PoseEstimate>& answers, RigFit& report);

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
