// The articulated subspace (issue #51): a key-point subspace built on the character's skinning,
// so that motion the training frames never showed — a limb turned further, a new shot — is still
// inside it.
//
// A linear blend skinning model (SSDR: Le & Deng 2012, through the project's own decomposition,
// core/animspace/skinning_decomposition.h) poses point i as
//   f_i = Σ_j w_ij M_j [p̂_i − c_j; 1],      M_j = [A_j | t_j] (3 × 4, any affine map),
// with p̂ the rest pose (the first training frame) and c_j bone j's rest centre (the weighted
// centroid of its points: the 12 numbers of a bone are then about as large as each other, which
// keeps the key rows conditioned at any model scale). With the weights fixed this is linear in
// the 12·B numbers of the M_j — Merry 2007 §2.1's observation that a skinned pose is a linear
// function of the skinning transforms — so the skinning model is a subspace basis L (3N × 12B)
// whose coordinates are the bone transforms. What skinning cannot express (a skirt, a bulging
// muscle) is left in the training frames' residuals E = T − L Q (each frame's transforms Q fitted
// to all its points by least squares), and their principal components R are appended:
//   f̂ = μ_E + [L | R] p,   p = (vec M_1 … vec M_B, residual coefficients).
// The runtime (pmsc_model.h) is the linear kind's: p from the key rows by least squares, one
// reconstruction for a batch, the same soft cache and calibration.
//
// What is not held out: the weights are fitted once on all training frames; the calibration's
// folds refit only the residual components. The bone transforms are per-pose unknowns either way.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/common/progress.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::pmsc {

// Coordinates per bone: the 3 × 4 affine matrix M_j, row-major (a00 a01 a02 t0 a10 …).
inline constexpr int kBoneCoordinates = 12;
// The key budget of an articulated model: enough keys for kKeyEquationsPerUnknown equations per
// coordinate, and never more than kMaxKeyFraction of the points (key_points.h; issue #51).
inline constexpr double kKeyEquationsPerUnknown = 4.5;
// Bones when the caller does not choose: 32 (the skinning benchmark fits horse-gallop's 48 frames
// with 30 bones within 1.3 of 100 units RMS, docs/BENCHMARKS.md; on crane's first 60%, 32 bones
// left 0.17% of the diagonal RMS where 24 left 0.22%), and never more than one bone per
// kPointsPerBone points, so that the key ceiling still gives kKeyEquationsPerUnknown equations
// for each bone's 12 numbers with room for the residual components:
// 12 · 4.5 / 3 = 18 keys per bone ≤ kMaxKeyFraction · 250 = 20.
inline constexpr int kArticulatedDefaultBones = 32;
inline constexpr int kPointsPerBone = 250;
// The skinning decomposition stops once an iteration lowers its error by less than this fraction:
// what the last percent would fit, the residual components take up (crane's first 60%, 32 bones:
// 0.173% of the diagonal RMS in 5 s, against 0.171% in 28 s at the decomposition's own 1e-3).
inline constexpr double kDecompositionTolerance = 1e-2;
// The residual components' count: the smallest r whose held-out projection error (blocks and
// interleaved frames the fold did not see) is within this fraction of the largest r's.
inline constexpr double kResidualHeldOutSlack = 0.05;

// B for N points when the caller asks for 0: kArticulatedDefaultBones, at most N / kPointsPerBone,
// at least 1.
int default_bone_count(long point_count);

// The skinning columns L (3N × 12B, point-major rows) of linear blend weights on `influences`
// (bones 1 … B; bone 0 is the root and has no columns), with `rest` (N × 3) and the bone centres
// `centres` (B × 3, bone j's in row j − 1).
Eigen::MatrixXd skinning_columns(const Eigen::MatrixX3d& rest, const animation_space::InfluenceSets& influences,
                                 const Eigen::VectorXd& weights, int bone_count, const Eigen::MatrixX3d& centres);

struct ArticulatedSkinning {
  int bone_count = 0;                     // B
  Eigen::MatrixXd columns;                // 3N × 12B, L
  Eigen::MatrixXd residuals;              // 3N × F, E = T − L Q
  double rms = 0;                         // RMS point error of L Q over all frames, model units
  // Per bone, up to four points that fix its 12 numbers (spread: the heaviest point of the bone,
  // the farthest from it, the farthest from their line, the farthest from their plane), bones in
  // order: the key selection's first seeds, so that no bone's transform is left to the
  // regularisation.
  std::vector<int> coverage_points;
};

// Fits the skinning of `frames` (F × 3N, F ≥ 2, rest pose = frame 0): rigid segmentation into
// `bone_count` parts, the skinning decomposition, then each frame's affine transforms by least
// squares over all its points. `faces` may be empty. Progress: the decomposition's iterations.
// Errors: kInvalidArgument naming the field (bone_count outside [1, N], shapes).
Result<ArticulatedSkinning> fit_articulated_skinning(const FrameMatrix& frames, const FaceMatrix& faces,
                                                     int bone_count, const ProgressCallback& progress = {});

}  // namespace animspace::pmsc
