// Distance metrics on animation space (Merry 2007 §3.3), keeping them valid when the model is
// scaled or moved (§3.4), and the pose-independent bounding sphere of §7.2.
//
//   L2,2 (§3.3.1–3.3.2): ‖s‖²₂,₂ = E[‖G s‖²] = sᵀ P s with P = E[GᵀG], the root-mean-square
//        model-space length of an animation-space vector s over the distribution of poses, and the
//        inner product ⟨s, t⟩₂,₂ = sᵀ P t. C = P^½ maps it to the Euclidean one.
//   L2,∞ (§3.3.3): ‖s‖₂,∞ ≥ ‖G s‖ for every pose allowed by per-joint bounds B[L_j]; found by
//        propagating bounding spheres from the leaves to the root (eqs. 3.20–3.28).
//
// Both norms are defined only for vectors of weight 0 (differences of two points, §3.3): the
// functions return kInvalidArgument for other vectors.
//
// The distribution of poses is given joint by joint (JointDistribution, the thesis's statistical
// models of §3.3.1) and P assembled by the O(b²) recursion of eqs. 3.7–3.8, which assumes the
// joint transforms L_j are independent; or P is averaged over example poses directly
// (metrics_from_poses), which needs no independence but only knows the poses it was given.
// Either way the result is an AnimationSpaceMetrics: everything §3.4 needs, so a model can be
// rescaled or moved later without the distributions it was computed from.
//
// Frames and conventions are those of skeleton.h: bone 0 is the root, its frame is model space
// and G_0 = I; L_j maps bone j's frame to its parent's; 4×4 affine matrices, column vectors. A
// matrix's "linear part" is its top-left 3×3 block (the thesis's overlined L̄), its
// "translation" the top-right 3×1 column (the underlined L̲). All computation is in double.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/geometry/bounding_sphere.h"

namespace animspace::animation_space {

// Absolute tolerance on the weight of a vector the norms require to have weight 0. Weights are
// dimensionless (they do not change when a model is scaled), and a difference of two vertices of
// a model that passes validate(model) (weights 1 to within 1e-6) must be accepted.
inline constexpr double kWeightZeroTolerance = 1e-6;

// ---------------------------------------------------------------------------------------------
// Statistical models of one joint (§3.3.1)
// ---------------------------------------------------------------------------------------------

enum class JointModel {
  // "Fixed skeleton": L_j = L̂_j, the rest joint transform, in every pose. The only model the
  // root (bone 0) may have.
  kFixed,
  // "Rotation and fixed translation", one degree of freedom: L_j = L̂_j · Rot(axis, φ) with φ
  // uniform in [angle_min, angle_max]; the rotation acts in bone j's rest frame about the joint
  // (bone j's origin), so the translation stays that of L̂_j. E[L̄_j] is eq. 3.14 for any axis.
  kAxisRange,
  // "Uniform distribution of rotations, fixed translations": L_j = L̂_j · R with R uniform
  // (Haar) over SO(3); E[L̄_j] = 0 and eq. 3.15.
  kUniformRotation,
  // Sampled from examples: L_j is drawn uniformly from `samples` (any affine transforms, so
  // scaling and moving joints are allowed), independently of the other joints.
  kSampled,
};

struct JointDistribution {
  JointModel kind = JointModel::kFixed;
  // kAxisRange only: unit axis in bone j's rest frame, and φ0 ≤ φ1 in radians (a range wider
  // than 2π is allowed: φ stays uniform, the rotation then is not).
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double angle_min = 0;
  double angle_max = 0;
  // kSampled only: example joint transforms L_j (bone j → parent frame), at least one.
  TransformList samples;
};

JointDistribution fixed_joint();
JointDistribution axis_range_joint(const Eigen::Vector3d& axis, double angle_min, double angle_max);
JointDistribution uniform_rotation_joint();
JointDistribution sampled_joint(TransformList samples);

// One distribution per bone from example poses: bone 0 kFixed, every other bone kSampled with
// the joint transforms L_j = G_φ(j)⁻¹ G_j of the poses.
//   poses  N ≥ 1 poses, each b global transforms G_j with G_0 = I (to 1e-9)
// Errors: kInvalidArgument for an invalid skeleton, no poses, or a pose that fails
// validate_pose or moves the root (naming the pose and bone).
Result<std::vector<JointDistribution>> sampled_joint_distributions(const Skeleton& skeleton,
                                                                   const std::vector<TransformList>& poses);

// E[Rot(axis, φ)] for φ uniform in [angle_min, angle_max]: eq. 3.14 for any unit axis a,
//   (sin φ1 − sin φ0)/(φ1−φ0) · (I − aaᵀ) + (cos φ0 − cos φ1)/(φ1−φ0) · [a]× + aaᵀ,
// evaluated in a form that stays accurate as φ1 − φ0 → 0 (it then tends to Rot(axis, φ0)).
// Errors: kInvalidArgument when |‖axis‖ − 1| > 1e-6, an angle is not finite, or φ0 > φ1.
Result<Eigen::Matrix3d> expected_axis_rotation(const Eigen::Vector3d& axis, double angle_min, double angle_max);

// ---------------------------------------------------------------------------------------------
// Precomputed metrics of a model
// ---------------------------------------------------------------------------------------------

// B[L_j] = M(s, v1, r1) (eq. 3.23 ff.): every allowed L_j has ‖L̄_j‖₂ ≤ s and a translation in
// the sphere S(v1, r1) (parent frame, model units).
struct JointBound {
  double linear_norm = 1;                                           // s ≥ 0
  Eigen::Vector3d translation_centre = Eigen::Vector3d::Zero();    // v1
  double translation_radius = 0;                                    // r1 ≥ 0
};

// Everything the norms, the bounding sphere and the §3.4 transforms need.
struct AnimationSpaceMetrics {
  // 4b × 4b, P = E[GᵀG], symmetric positive semi-definite. Block (i, j) is E[G_iᵀG_j]; the
  // blocks (0, j) are E[G_j], which §3.4.2 needs.
  Eigen::MatrixXd P;
  // b entries, E[L_j]; E[L_0] = I.
  TransformList expected_joints;
  // b entries, B[L_j]; entry 0 is unused (the root does not move) and is the identity bound.
  std::vector<JointBound> joint_bounds;

  int bone_count() const { return static_cast<int>(joint_bounds.size()); }
};

// P by the independent-joints recursion (eqs. 3.7–3.8), with E[G_jᵀG_j] = E[L_jᵀ E[G_φ(j)ᵀG_φ(j)] L_j]
// evaluated exactly for each joint model (eqs. 3.10–3.12 with the joint's own moments). For the
// rotation models this is eq. 3.13 (kAxisRange) and eq. 3.15 (kUniformRotation) when the ancestors
// only rotate, and stays exact when a sampled ancestor scales. Bounds: s = ‖L̂̄_j‖₂ (1 for a rigid
// rest skeleton) and S(L̲̂_j, 0) for the three rest-based models; for kSampled the largest ‖L̄‖₂ of
// the samples and a sphere around the samples' translations (centred on their mean: not minimal,
// but it moves with the samples under §3.4's transforms).
//   distributions  b entries, one per bone; entry 0 must be kFixed
// Errors: kInvalidArgument naming the bone for an invalid skeleton, a count mismatch, a bad axis
// or range (see expected_axis_rotation), an empty or non-affine sample list, a moving root.
Result<AnimationSpaceMetrics> metrics_from_joint_distributions(const Skeleton& skeleton,
                                                               const std::vector<JointDistribution>& distributions);

// P = (1/N) Σ_n G⁽ⁿ⁾ᵀG⁽ⁿ⁾ averaged over the example poses themselves, with no independence
// assumption (correlated joints are captured, unseen combinations are not); E[L_j] the mean
// joint transform and B[L_j] as for kSampled. Cost O(N b²).
//   poses  N ≥ 1 poses, each b global transforms with G_0 = I (to 1e-9)
// Errors: as sampled_joint_distributions.
Result<AnimationSpaceMetrics> metrics_from_poses(const Skeleton& skeleton, const std::vector<TransformList>& poses);

// Checks sizes against `bone_count`, finiteness, symmetry of P (to 1e-9 relative to its largest
// entry), affine E[L_j], non-negative bounds. The norm functions below check only the sizes they
// index with; call this once on metrics that come from outside (e.g. a file).
// Errors: kInvalidArgument naming the part.
Status validate(const AnimationSpaceMetrics& metrics, int bone_count);

// ---------------------------------------------------------------------------------------------
// Norms
// ---------------------------------------------------------------------------------------------

// A sparse animation-space vector: 4-vectors s_j on the listed bones (strictly increasing), zero
// on the others — the form a model's vertices and their differences have.
struct SparseAnimationVector {
  std::vector<int32_t> bones;
  Eigen::Matrix<double, 4, Eigen::Dynamic> vectors;  // 4 × bones.size()

  double weight() const { return vectors.row(3).sum(); }
};

// p_a − p_b for two vertices of `model` (weight 0 when both have weight 1). Vertex indices are
// asserted to be in range.
SparseAnimationVector vertex_difference(const AnimationSpaceModel& model, int vertex_a, int vertex_b);

// ‖s‖₂,₂ = √(sᵀPs) (§3.3.1). s is a dense 4b-vector or sparse; its weight must be 0 (within
// kWeightZeroTolerance). A result of sᵀPs in (−ε, 0) from rounding on a null vector of P
// (Appendix B.3) reads as 0.
// Errors: kInvalidArgument for a wrong size / bone index, a non-finite entry or a non-zero weight.
Result<double> l22_norm(const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s);
Result<double> l22_norm(const AnimationSpaceMetrics& metrics, const SparseAnimationVector& s);

// ⟨s, t⟩₂,₂ = sᵀPt, the expected model-space dot product of G s and G t (eq. 3.16). Same
// requirements and errors as l22_norm, for both vectors.
Result<double> l22_inner_product(const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s,
                                 const Eigen::VectorXd& t);
Result<double> l22_inner_product(const AnimationSpaceMetrics& metrics, const SparseAnimationVector& s,
                                 const SparseAnimationVector& t);

// C = P^½ (4b × 4b, symmetric), so that (Cs)·(Ct) = ⟨s, t⟩₂,₂ ("normalised animation space",
// §3.3.2), from the eigendecomposition of P. Eigenvalues in [−1e-9 λ_max, 0) are rounding on
// P's null space (Appendix B.3: every fixed-translation model has one) and become 0.
// Errors: kInvalidArgument if P is not square, not finite, not symmetric (1e-9 relative), or has
// an eigenvalue below −1e-9 λ_max (not positive semi-definite).
Result<Eigen::MatrixXd> normalised_animation_space_matrix(const Eigen::MatrixXd& P);

// ‖s‖₂,∞ (§3.3.3): spheres S_w(v, r) start as {s_j} in every bone frame and move to the parent
// by eq. 3.27, B[L_j] S_w(v, r) = S_w(w v1, s‖v‖ + s r + |w| r1) (|w|: intermediate weights may
// be negative), and add by eq. 3.28; at the root (model space, G_0 = I) the norm is ‖v‖ + r.
// ‖G s‖ ≤ ‖s‖₂,∞ for every pose whose joints satisfy metrics.joint_bounds. Cost O(b) per vector
// (sparse: only the influenced bones and their ancestors).
// Errors: as l22_norm, plus a skeleton whose bone count differs from the metrics'.
Result<double> l2inf_norm(const Skeleton& skeleton, const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s);
Result<double> l2inf_norm(const Skeleton& skeleton, const AnimationSpaceMetrics& metrics,
                          const SparseAnimationVector& s);

// ---------------------------------------------------------------------------------------------
// Bounding sphere for culling (§7.2)
// ---------------------------------------------------------------------------------------------

// A sphere containing every vertex of `model` in every pose allowed by metrics.joint_bounds.
// Centre: the expected model-space position of the vertex centroid under uniform rotations with
// rest translations (whatever distribution the metrics came from — §7.2 avoids its bias), a point
// only the root moves; radius: the largest ‖p_i − c‖₂,∞ with c placed on bone 0 with weight 1.
// Cost O(V · depth).
// Errors: kInvalidArgument for an invalid model, no vertices, or metrics of another bone count.
Result<geometry::BoundingSphere> pose_bounding_sphere(const AnimationSpaceModel& model, const AnimationSpaceMetrics& metrics);

// ---------------------------------------------------------------------------------------------
// Transforming a model with its metrics (§3.4)
// ---------------------------------------------------------------------------------------------

// Scales the model uniformly by `scale` about the model-space origin (eq. 3.29): p̄_j ← s p̄_j
// for positions and tangents, rest translations Ĝ̲_j ← s Ĝ̲_j (so L̲_j ← s L̲_j, eq. 3.30),
// E[L̲_j] ← s E[L̲_j], P blocks by eq. 3.31, translation spheres scaled. Posed with joint
// translations scaled by s, the new model gives s·v for every vertex.
// Errors: kInvalidArgument (nothing is changed) for `scale` not finite and > 0, a model that fails
// validate(model), or metrics that fail validate(metrics, b).
Status scale_model(double scale, AnimationSpaceModel& model, AnimationSpaceMetrics& metrics);

// Rotates and translates the model by the rigid transform M (§3.4.2): sub-root joints
// L_j ← M L_j (so G_j ← M G_j for every non-root bone, and Ĝ_j ← M Ĝ_j), root influences
// p_0 ← M p_0 (eq. 3.32), E[L_j] and translation spheres of sub-root joints moved by M, P by
// eq. 3.33 with E[G_j] read from P's blocks (0, j). Posed with the sub-root joints composed with
// M, the new model gives M·v for every vertex.
// Errors: kInvalidArgument (nothing is changed) when M is not finite and affine with a rotation
// (orthonormal to 1e-9, determinant +1) as its linear part, a model that fails validate(model), or
// metrics that fail validate(metrics, b).
Status rigid_transform_model(const Transform& M, AnimationSpaceModel& model, AnimationSpaceMetrics& metrics);

}  // namespace animspace::animation_space
