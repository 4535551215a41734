// Skeleton fitting: bone motions and rest joints from example meshes (Merry 2007 §4.1.4,
// after James & Twigg 2005).
//
// The user supplies a hierarchy, a set of core vertices per bone (vertices that move rigidly
// with it) and rough joint positions u_j. For every bone and example the affine map that best
// moves the bone's core vertices from the reference mesh to the example is fitted (eq. 4.5), its
// linear part replaced by the rotation of its polar decomposition M̄ = R S (a reflection is
// turned into a rotation by negating S's smallest eigenvalue) and the translation refitted. The
// rest transforms Ĝ_j are then pure translations h_j chosen so that the joint translations L̲_j^p
// vary as little as possible over the examples (eq. 4.6), plus λ (h_j − u_j) = 0 for joints the
// motion leaves undetermined (a hinge's axis). The example poses are G^p_j = M^p_j Ĝ_j.
//
// Precision: double throughout; the points arrive as float.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

// The rigid transform M (rotation + translation) that moves `rest` onto `posed` (both 3 × N,
// N ≥ 3 points in correspondence, not all on one line) by §4.1.4's recipe: affine least squares
// (eq. 4.5), the rotation of its polar decomposition with the reflection fix, then the
// least-squares translation for that rotation. det R = +1 always. Directions in which the rest
// points have (relative) spread below 1e-4 of the largest, e.g. the normal of coplanar points,
// are left out of the affine fit rather than amplifying noise. `reflection_fixed` (nullable) is
// set when the polar factor was a reflection.
Transform fit_rigid_motion(const Eigen::Matrix3Xd& rest, const Eigen::Matrix3Xd& posed, bool* reflection_fixed = nullptr);

// Whether the points (3 × N) determine a rigid motion: N ≥ 3 and not on one line (second
// principal spread ≥ 1e-4 of the largest).
bool determines_rigid_motion(const Eigen::Matrix3Xd& points);

struct SkeletonFitOptions {
  // λ of §4.1.4 (10⁻³ in all the thesis's results). Dimensionless: both the translation variance
  // and λ (h_j − u_j) are lengths. ≥ 0; 0 leaves a hinge's joint anywhere on its axis
  // (kFailedPrecondition if that happens).
  double joint_regularisation = 1e-3;
  // A bone whose core vertices do not determine a rigid motion (fewer than 3, or all on one
  // line): false → kInvalidArgument naming the bone; true → the bone moves with its parent
  // (M^p_j = M^p_φ(j), identity under the root) and its joint stays at u_j; such bones are
  // listed in the report.
  bool inherit_undetermined_bones = false;
};

// The second half of skeleton fitting on its own, for motions found another way (skinning
// decomposition): rest joints h_j from the rigid motions M^p_j (n examples × b bones, M^p_0 = I) by
// eq. 4.6 with λ = `joint_regularisation` pulling h_j towards u_j (the translation of
// user_skeleton.rest[j]). Returns the skeleton with user_skeleton's hierarchy and names and
// Ĝ_j = translation h_j; `joint_spread` (nullable) gets the per-bone spread as in
// SkeletonFitReport. Errors: kFailedPrecondition when λ = 0 and a joint is undetermined.
Result<Skeleton> skeleton_from_motions(const Skeleton& user_skeleton, const std::vector<TransformList>& motions,
                                       double joint_regularisation, std::vector<double>* joint_spread = nullptr);

struct SkeletonFitReport {
  // Per bone (b entries; 0 for the root and for inherited bones): RMS distance between the core
  // vertices and their rigidly moved reference positions over all examples, model units.
  std::vector<double> rigid_rms;
  // Per bone: RMS over examples of ‖L̲_j^p − m_j‖, the spread of the joint translation that
  // eq. 4.6 minimises (0 for a joint that is a pure rotation centre), model units.
  std::vector<double> joint_spread;
  std::vector<int32_t> inherited_bones;  // bones that moved with their parent (see options)
  int reflections_fixed = 0;             // polar factors that were reflections, over bones × examples
  double seconds = 0;
};

struct FittedSkeleton {
  Skeleton skeleton;                   // hierarchy and names of the input; Ĝ_j = translation h_j
  std::vector<TransformList> poses;    // n × b: G^p_j = M^p_j Ĝ_j (G^p_0 = I)
  std::vector<TransformList> motions;  // n × b: the rigid M^p_j (rest → example p; M^p_0 = I)
};

// `reference_points`: V × 3, the reference (rest) mesh. `meshes`: n × 3V, n ≥ 1 examples in
// correspondence with it (row p = x0 y0 z0 x1 …). `user_skeleton`: the hierarchy (and names);
// u_j is the translation of its rest transform Ĝ_j, whose rotation is ignored. `core_vertices`:
// b lists of vertex indices; list 0 must be empty (the root is fixed, G_0 = I, §2.1).
// Errors: kInvalidArgument naming the input (sizes, NaN/Inf, invalid skeleton, an index out of
// range, core vertices on the root, a bone with an undetermined motion unless inherited,
// negative λ); kFailedPrecondition when λ = 0 and a joint position is undetermined.
Result<FittedSkeleton> fit_skeleton(const PointMatrix& reference_points, const FrameMatrix& meshes,
                                    const Skeleton& user_skeleton,
                                    const std::vector<std::vector<int32_t>>& core_vertices,
                                    const SkeletonFitOptions& options = {}, SkeletonFitReport* report = nullptr);

}  // namespace animspace::animation_space
