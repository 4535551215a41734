// Merry 2007, "Animation space" (PhD thesis): §3.3 distance metrics, §3.4 transforming a model,
// §7.2 frustum culling; Appendix B.2 (E[RᵀMR] for uniform R) and B.3 (null space of P).
#include "core/animspace/metrics.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>

namespace animspace::animation_space {
namespace {

// |‖axis‖ − 1| allowed for a kAxisRange axis: loose enough for an axis normalised in float.
constexpr double kAxisUnitTolerance = 1e-6;
// How far from I a pose's G_0 may be (the root frame is model space, §3.1).
constexpr double kRootIdentityTolerance = 1e-9;
// Symmetry of P, relative to its largest entry: the recursion and the sums build P symmetric up
// to rounding, so anything larger is a corrupt matrix.
constexpr double kSymmetryTolerance = 1e-9;
// Eigenvalues of P above −kEigenvalueTolerance·λ_max count as rounding of a true 0. Rounding in
// a 4b × 4b symmetric eigensolver is O(4b · ε · λ_max) ≈ 1e-13 λ_max for b = 100, so this leaves
// four orders of margin while still catching a matrix that is genuinely indefinite.
constexpr double kEigenvalueTolerance = 1e-9;
// Orthonormality of a rigid transform's linear part (max-entry of RᵀR − I).
constexpr double kRotationTolerance = 1e-9;

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

std::string bone_label(int bone) { return "bone " + std::to_string(bone); }

bool is_affine(const Transform& m) {
  return m.allFinite() && m(3, 0) == 0.0 && m(3, 1) == 0.0 && m(3, 2) == 0.0 && m(3, 3) == 1.0;
}

double spectral_norm(const Eigen::Matrix3d& A) {
  return Eigen::JacobiSVD<Eigen::Matrix3d>(A).singularValues()(0);
}

Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& a) {
  Eigen::Matrix3d K;
  K << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return K;
}

// sin(x)/x; sin is accurate to relative rounding for small x, so only x = 0 needs care.
double sinc(double x) { return x == 0.0 ? 1.0 : std::sin(x) / x; }

// Rot(a, φ) = aaᵀ + cos φ (I − aaᵀ) + sin φ [a]× (Rodrigues) is linear in w = (1, cos φ, sin φ),
// so its first and second moments over φ ~ U[φ0, φ1] need only E[w] and E[w wᵀ]. Written with
// the mid-angle m and half-width h so that a narrow range does not cancel: e.g.
// (sin φ1 − sin φ0)/(φ1 − φ0) = cos m · sinc h.
struct AxisRotationMoments {
  Eigen::Matrix3d U[3];  // aaᵀ, I − aaᵀ, [a]×
  Eigen::Vector3d mean;  // E[w]
  Eigen::Matrix3d second;  // E[w wᵀ]
};

AxisRotationMoments axis_rotation_moments(const Eigen::Vector3d& unit_axis, double angle_min, double angle_max) {
  // The axis passed the 1e-6 unit check; renormalise so that Rot stays orthonormal to rounding.
  const Eigen::Vector3d axis = unit_axis.normalized();
  AxisRotationMoments moments;
  moments.U[0] = axis * axis.transpose();
  moments.U[1] = Eigen::Matrix3d::Identity() - moments.U[0];
  moments.U[2] = cross_matrix(axis);
  const double m = 0.5 * (angle_min + angle_max);
  const double h = 0.5 * (angle_max - angle_min);
  const double c = std::cos(m) * sinc(h);                   // E[cos φ]
  const double s = std::sin(m) * sinc(h);                   // E[sin φ]
  const double c2 = 0.5 * std::cos(2 * m) * sinc(2 * h);    // E[cos 2φ] / 2
  const double s2 = 0.5 * std::sin(2 * m) * sinc(2 * h);    // E[sin 2φ] / 2
  moments.mean = Eigen::Vector3d(1, c, s);
  moments.second << 1, c, s,        //
      c, 0.5 + c2, s2,              // E[cos²] = ½ + ½E[cos 2φ], E[cos sin] = ½E[sin 2φ]
      s, s2, 0.5 - c2;              // E[sin²] = ½ − ½E[cos 2φ]
  return moments;
}

Eigen::Matrix3d expected_rotation(const AxisRotationMoments& moments) {
  return moments.mean(0) * moments.U[0] + moments.mean(1) * moments.U[1] + moments.mean(2) * moments.U[2];
}

// E[Xᵀ A X] for X = Rot(a, φ): Σ_pq E[w_p w_q] U_pᵀ A U_q.
Eigen::Matrix3d expected_rotation_congruence(const AxisRotationMoments& moments, const Eigen::Matrix3d& A) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (int p = 0; p < 3; ++p) {
    for (int q = 0; q < 3; ++q) sum += moments.second(p, q) * (moments.U[p].transpose() * A * moments.U[q]);
  }
  return sum;
}

Status check_axis_range(const Eigen::Vector3d& axis, double angle_min, double angle_max, const std::string& where) {
  if (!axis.allFinite() || std::abs(axis.norm() - 1.0) > kAxisUnitTolerance) {
    return invalid(where + "rotation axis has length " + std::to_string(axis.norm()) +
                   ", expected a unit vector (to " + std::to_string(kAxisUnitTolerance) + ")");
  }
  if (!std::isfinite(angle_min) || !std::isfinite(angle_max)) {
    return invalid(where + "rotation range [" + std::to_string(angle_min) + ", " + std::to_string(angle_max) +
                   "] is not finite");
  }
  if (angle_min > angle_max) {
    return invalid(where + "rotation range has φ0 = " + std::to_string(angle_min) + " > φ1 = " +
                   std::to_string(angle_max) + ", expected φ0 ≤ φ1");
  }
  return Status::Ok();
}

// B[L] for a set of example joint transforms: the largest ‖L̄‖₂, and a sphere around the
// translations centred on their mean. Not the minimal sphere (at most twice its radius: the mean
// lies inside it), but it moves with a rigid transform or a scaling of the samples, so §3.4's
// updates of a bound equal the bound of the updated samples.
JointBound sample_bound(const TransformList& samples) {
  JointBound bound;
  bound.linear_norm = 0;
  for (const Transform& L : samples) {
    bound.linear_norm = std::max(bound.linear_norm, spectral_norm(L.topLeftCorner<3, 3>()));
    bound.translation_centre += L.topRightCorner<3, 1>();
  }
  bound.translation_centre /= static_cast<double>(samples.size());
  for (const Transform& L : samples) {
    bound.translation_radius =
        std::max(bound.translation_radius, (L.topRightCorner<3, 1>() - bound.translation_centre).norm());
  }
  return bound;
}

Status check_poses(const Skeleton& skeleton, const std::vector<TransformList>& poses) {
  ANIMSPACE_RETURN_IF_ERROR(validate(skeleton));
  if (poses.empty()) return invalid("no example poses; expected at least one");
  for (size_t n = 0; n < poses.size(); ++n) {
    const std::string what = "pose " + std::to_string(n);
    ANIMSPACE_RETURN_IF_ERROR(validate_pose(skeleton, poses[n], what));
    if (!poses[n][0].isIdentity(kRootIdentityTolerance)) {
      return invalid(what + ": transform of bone 0 (the root) must be the identity, its frame is model space");
    }
  }
  return Status::Ok();
}

// The per-joint part of the independent-joints recursion for one joint of a rest-based model
// (kFixed, kAxisRange, kUniformRotation), where L = [L̂̄ X, L̲̂; 0 1] with X the random rotation.
struct RestBasedJoint {
  JointModel kind;
  Eigen::Matrix3d rest_linear;
  Eigen::Vector3d rest_translation;
  AxisRotationMoments axis;  // kAxisRange only
};

Eigen::Matrix3d expected_linear(const RestBasedJoint& joint) {
  switch (joint.kind) {
    case JointModel::kAxisRange:
      return joint.rest_linear * expected_rotation(joint.axis);
    case JointModel::kUniformRotation:
      return Eigen::Matrix3d::Zero();  // eq. 3.15 context: E[R] = 0 under the Haar measure
    default:
      return joint.rest_linear;
  }
}

// E[Lᵀ Q L] for symmetric Q = [A b; bᵀ q] (eqs. 3.10–3.12 with fixed translation t = L̲̂):
//   [ E[XᵀL̂̄ᵀ A L̂̄X]              E[X]ᵀL̂̄ᵀ(A t + b) ]
//   [ (A t + b)ᵀL̂̄ E[X]       tᵀAt + 2bᵀt + q     ]
Eigen::Matrix4d expected_congruence(const RestBasedJoint& joint, const Eigen::Matrix4d& Q) {
  const Eigen::Matrix3d A = Q.topLeftCorner<3, 3>();
  const Eigen::Vector3d b = Q.topRightCorner<3, 1>();
  const Eigen::Vector3d& t = joint.rest_translation;
  const Eigen::Matrix3d A_rest = joint.rest_linear.transpose() * A * joint.rest_linear;
  Eigen::Matrix3d linear;
  switch (joint.kind) {
    case JointModel::kAxisRange:
      linear = expected_rotation_congruence(joint.axis, A_rest);
      break;
    case JointModel::kUniformRotation:
      linear = (A_rest.trace() / 3.0) * Eigen::Matrix3d::Identity();  // Appendix B.2, eq. B.8
      break;
    default:
      linear = A_rest;
      break;
  }
  const Eigen::Vector3d cross = expected_linear(joint).transpose() * (A * t + b);
  Eigen::Matrix4d out;
  out.topLeftCorner<3, 3>() = 0.5 * (linear + linear.transpose());
  out.topRightCorner<3, 1>() = cross;
  out.bottomLeftCorner<1, 3>() = cross.transpose();
  out(3, 3) = t.dot(A * t) + 2 * b.dot(t) + Q(3, 3);
  return out;
}

// Whole-vector checks shared by every norm.
Status check_weight(double weight, const char* name) {
  if (!(std::abs(weight) <= kWeightZeroTolerance)) {
    return invalid(std::string(name) + " has weight " + std::to_string(weight) +
                   ", expected 0 (the norms are defined on differences of points, Merry 2007 §3.3)");
  }
  return Status::Ok();
}

Status check_dense(const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s, const char* name) {
  if (s.size() != metrics.P.rows() || s.size() % 4 != 0) {
    return invalid(std::string(name) + " has " + std::to_string(s.size()) + " entries, expected 4b = " +
                   std::to_string(metrics.P.rows()));
  }
  if (!s.allFinite()) return invalid(std::string(name) + " has a NaN or infinite entry");
  double weight = 0;
  for (Eigen::Index j = 0; j < s.size() / 4; ++j) weight += s(4 * j + 3);
  return check_weight(weight, name);
}

Status check_sparse(int bone_count, const SparseAnimationVector& s, const char* name) {
  if (static_cast<size_t>(s.vectors.cols()) != s.bones.size()) {
    return invalid(std::string(name) + " has " + std::to_string(s.bones.size()) + " bones but " +
                   std::to_string(s.vectors.cols()) + " 4-vectors");
  }
  for (size_t k = 0; k < s.bones.size(); ++k) {
    const int bone = s.bones[k];
    if (bone < 0 || bone >= bone_count) {
      return invalid(std::string(name) + ": bone " + std::to_string(bone) + " is outside 0 … " +
                     std::to_string(bone_count - 1));
    }
    if (k > 0 && bone <= s.bones[k - 1]) return invalid(std::string(name) + ": bones must be strictly increasing");
  }
  if (!s.vectors.allFinite()) return invalid(std::string(name) + " has a NaN or infinite entry");
  return check_weight(s.weight(), name);
}

Status check_bone_count(const AnimationSpaceMetrics& metrics, int bone_count) {
  if (metrics.bone_count() != bone_count || metrics.P.rows() != 4L * bone_count ||
      static_cast<int>(metrics.expected_joints.size()) != bone_count) {
    return invalid("metrics are for " + std::to_string(metrics.bone_count()) + " bones (P is " +
                   std::to_string(metrics.P.rows()) + " × " + std::to_string(metrics.P.cols()) +
                   "), the skeleton has " + std::to_string(bone_count));
  }
  return Status::Ok();
}

SparseAnimationVector sparse_from_dense(const Eigen::VectorXd& s) {
  SparseAnimationVector sparse;
  std::vector<Eigen::Vector4d> columns;
  for (Eigen::Index j = 0; j < s.size() / 4; ++j) {
    if (s.segment<4>(4 * j).isZero(0.0)) continue;
    sparse.bones.push_back(static_cast<int32_t>(j));
    columns.push_back(s.segment<4>(4 * j));
  }
  sparse.vectors.resize(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) sparse.vectors.col(static_cast<Eigen::Index>(k)) = columns[k];
  return sparse;
}

double sparse_form(const Eigen::MatrixXd& P, const SparseAnimationVector& s, const SparseAnimationVector& t) {
  double sum = 0;
  for (size_t a = 0; a < s.bones.size(); ++a) {
    for (size_t b = 0; b < t.bones.size(); ++b) {
      sum += s.vectors.col(static_cast<Eigen::Index>(a)).dot(
          P.block<4, 4>(4L * s.bones[a], 4L * t.bones[b]) * t.vectors.col(static_cast<Eigen::Index>(b)));
    }
  }
  return sum;
}

// sᵀPs ≥ 0 in exact arithmetic; a small negative value is rounding on (near) a null vector.
double norm_from_square(double square) { return std::sqrt(std::max(0.0, square)); }

// S_w(v, r) of eq. 3.22: a sphere of 3-vectors with a fixed weight w.
struct WeightedSphere {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0;
  double weight = 0;
};

// Reused between the vectors of one call (pose_bounding_sphere runs one per vertex).
class SpherePropagation {
 public:
  SpherePropagation(const Skeleton& skeleton, const std::vector<JointBound>& bounds)
      : parents_(skeleton.parents), bounds_(bounds), volumes_(parents_.size()), active_(parents_.size(), 0) {}

  // ‖s‖₂,∞ for a checked s.
  double norm(const SparseAnimationVector& s) {
    // Every influenced bone and its ancestors take part; the others contribute S_0(0, 0).
    for (const int32_t bone : s.bones) {
      for (int j = bone; j >= 0 && !active_[static_cast<size_t>(j)]; j = parents_[static_cast<size_t>(j)]) {
        active_[static_cast<size_t>(j)] = 1;
        volumes_[static_cast<size_t>(j)] = WeightedSphere{};
        order_.push_back(j);
      }
    }
    if (!active_[0]) {
      active_[0] = 1;
      volumes_[0] = WeightedSphere{};
      order_.push_back(0);
    }
    for (size_t k = 0; k < s.bones.size(); ++k) {
      WeightedSphere& volume = volumes_[static_cast<size_t>(s.bones[k])];
      volume.centre = s.vectors.col(static_cast<Eigen::Index>(k)).head<3>();
      volume.weight = s.vectors(3, static_cast<Eigen::Index>(k));
    }
    // Children have larger indices than their parents: descending order folds every child into
    // its parent before the parent moves on (eq. 3.20).
    std::sort(order_.begin(), order_.end(), std::greater<>());
    for (const int j : order_) {
      if (j == 0) continue;
      const WeightedSphere& child = volumes_[static_cast<size_t>(j)];
      const JointBound& bound = bounds_[static_cast<size_t>(j)];
      WeightedSphere& parent = volumes_[static_cast<size_t>(parents_[static_cast<size_t>(j)])];
      // eq. 3.27 (with |w|: a sub-sum may have negative weight), then eq. 3.28.
      parent.centre += child.weight * bound.translation_centre;
      parent.radius += bound.linear_norm * (child.centre.norm() + child.radius) +
                       std::abs(child.weight) * bound.translation_radius;
      parent.weight += child.weight;
    }
    const double result = volumes_[0].centre.norm() + volumes_[0].radius;
    for (const int j : order_) active_[static_cast<size_t>(j)] = 0;
    order_.clear();
    return result;
  }

 private:
  const std::vector<int32_t>& parents_;
  const std::vector<JointBound>& bounds_;
  std::vector<WeightedSphere> volumes_;
  std::vector<uint8_t> active_;
  std::vector<int> order_;
};

// Rest-based joint description of bone j (j ≥ 1) for a checked distribution.
RestBasedJoint rest_based_joint(const JointDistribution& distribution, const Transform& rest_joint) {
  RestBasedJoint joint;
  joint.kind = distribution.kind;
  joint.rest_linear = rest_joint.topLeftCorner<3, 3>();
  joint.rest_translation = rest_joint.topRightCorner<3, 1>();
  if (distribution.kind == JointModel::kAxisRange) {
    joint.axis = axis_rotation_moments(distribution.axis, distribution.angle_min, distribution.angle_max);
  }
  return joint;
}

Status check_distribution(const JointDistribution& distribution, int bone) {
  const std::string where = bone_label(bone) + ": ";
  switch (distribution.kind) {
    case JointModel::kFixed:
    case JointModel::kUniformRotation:
      break;
    case JointModel::kAxisRange:
      ANIMSPACE_RETURN_IF_ERROR(
          check_axis_range(distribution.axis, distribution.angle_min, distribution.angle_max, where));
      break;
    case JointModel::kSampled:
      if (distribution.samples.empty()) return invalid(where + "sampled joint model has no samples");
      for (size_t n = 0; n < distribution.samples.size(); ++n) {
        if (!is_affine(distribution.samples[n])) {
          return invalid(where + "sample " + std::to_string(n) +
                         " is not a finite affine transform (last row 0 0 0 1)");
        }
      }
      break;
    default:
      return invalid(where + "unknown joint model " + std::to_string(static_cast<int>(distribution.kind)));
  }
  return Status::Ok();
}

}  // namespace

// -------------------------------------------------------------------------------------------
// Joint models
// -------------------------------------------------------------------------------------------

JointDistribution fixed_joint() { return JointDistribution{}; }

JointDistribution axis_range_joint(const Eigen::Vector3d& axis, double angle_min, double angle_max) {
  JointDistribution distribution;
  distribution.kind = JointModel::kAxisRange;
  distribution.axis = axis;
  distribution.angle_min = angle_min;
  distribution.angle_max = angle_max;
  return distribution;
}

JointDistribution uniform_rotation_joint() {
  JointDistribution distribution;
  distribution.kind = JointModel::kUniformRotation;
  return distribution;
}

JointDistribution sampled_joint(TransformList samples) {
  JointDistribution distribution;
  distribution.kind = JointModel::kSampled;
  distribution.samples = std::move(samples);
  return distribution;
}

Result<std::vector<JointDistribution>> sampled_joint_distributions(const Skeleton& skeleton,
                                                                   const std::vector<TransformList>& poses) {
  ANIMSPACE_RETURN_IF_ERROR(check_poses(skeleton, poses));
  const size_t b = skeleton.parents.size();
  std::vector<JointDistribution> distributions(b);
  for (size_t j = 1; j < b; ++j) {
    distributions[j].kind = JointModel::kSampled;
    distributions[j].samples.reserve(poses.size());
  }
  for (const TransformList& pose : poses) {
    const TransformList joints = joint_transforms(skeleton, pose);
    for (size_t j = 1; j < b; ++j) distributions[j].samples.push_back(joints[j]);
  }
  return distributions;
}

Result<Eigen::Matrix3d> expected_axis_rotation(const Eigen::Vector3d& axis, double angle_min, double angle_max) {
  ANIMSPACE_RETURN_IF_ERROR(check_axis_range(axis, angle_min, angle_max, ""));
  return Eigen::Matrix3d(expected_rotation(axis_rotation_moments(axis, angle_min, angle_max)));
}

// -------------------------------------------------------------------------------------------
// Precomputation
// -------------------------------------------------------------------------------------------

Result<AnimationSpaceMetrics> metrics_from_joint_distributions(const Skeleton& skeleton,
                                                               const std::vector<JointDistribution>& distributions) {
  // Phase 1: check everything before any work.
  ANIMSPACE_RETURN_IF_ERROR(validate(skeleton));
  const int b = skeleton.bone_count();
  if (static_cast<int>(distributions.size()) != b) {
    return invalid("expected one joint distribution per bone (" + std::to_string(b) + "), got " +
                   std::to_string(distributions.size()));
  }
  if (distributions[0].kind != JointModel::kFixed) {
    return invalid("bone 0: the root does not animate (its frame is model space, G_0 = I); its joint model must be "
                   "fixed");
  }
  for (int j = 1; j < b; ++j) ANIMSPACE_RETURN_IF_ERROR(check_distribution(distributions[static_cast<size_t>(j)], j));

  // Phase 2: per joint, E[L_j] and B[L_j].
  const TransformList rest_joints = rest_joint_transforms(skeleton);
  AnimationSpaceMetrics metrics;
  metrics.expected_joints.assign(static_cast<size_t>(b), Transform::Identity());
  metrics.joint_bounds.assign(static_cast<size_t>(b), JointBound{});
  std::vector<RestBasedJoint> rest_based(static_cast<size_t>(b));
  for (size_t j = 1; j < static_cast<size_t>(b); ++j) {
    const JointDistribution& distribution = distributions[j];
    if (distribution.kind == JointModel::kSampled) {
      Transform sum = Transform::Zero();
      for (const Transform& L : distribution.samples) sum += L;
      metrics.expected_joints[j] = sum / static_cast<double>(distribution.samples.size());
      metrics.expected_joints[j].row(3) << 0, 0, 0, 1;  // exact, not a rounded mean
      metrics.joint_bounds[j] = sample_bound(distribution.samples);
      continue;
    }
    rest_based[j] = rest_based_joint(distribution, rest_joints[j]);
    metrics.expected_joints[j].topLeftCorner<3, 3>() = expected_linear(rest_based[j]);
    metrics.expected_joints[j].topRightCorner<3, 1>() = rest_based[j].rest_translation;
    metrics.joint_bounds[j] = JointBound{spectral_norm(rest_based[j].rest_linear), rest_based[j].rest_translation, 0.0};
  }

  // Phase 3: P block by block (eqs. 3.7–3.8). Once bone k is reached every block (i, j) with
  // i, j < k is known; for i < k, k is not an ancestor of i, so L_k is independent of G_i and
  // G_φ(k) and E[G_iᵀG_k] = E[G_iᵀG_φ(k)] E[L_k]. The diagonal needs the joint's second moments:
  // E[G_kᵀG_k] = E[L_kᵀ E[G_φ(k)ᵀG_φ(k)] L_k].
  Eigen::MatrixXd& P = metrics.P;
  P.setZero(4L * b, 4L * b);
  P.topLeftCorner<4, 4>().setIdentity();
  for (int k = 1; k < b; ++k) {
    const int parent = skeleton.parents[static_cast<size_t>(k)];
    const Transform& expected_joint = metrics.expected_joints[static_cast<size_t>(k)];
    for (int i = 0; i < k; ++i) {
      const Eigen::Matrix4d block = P.block<4, 4>(4L * i, 4L * parent) * expected_joint;
      P.block<4, 4>(4L * i, 4L * k) = block;
      P.block<4, 4>(4L * k, 4L * i) = block.transpose();
    }
    const Eigen::Matrix4d Q = P.block<4, 4>(4L * parent, 4L * parent);
    const JointDistribution& distribution = distributions[static_cast<size_t>(k)];
    Eigen::Matrix4d diagonal;
    if (distribution.kind == JointModel::kSampled) {
      diagonal.setZero();
      for (const Transform& L : distribution.samples) diagonal.noalias() += L.transpose() * Q * L;
      diagonal /= static_cast<double>(distribution.samples.size());
      diagonal = (0.5 * (diagonal + diagonal.transpose())).eval();
    } else {
      diagonal = expected_congruence(rest_based[static_cast<size_t>(k)], Q);
    }
    P.block<4, 4>(4L * k, 4L * k) = diagonal;
  }
  return metrics;
}

Result<AnimationSpaceMetrics> metrics_from_poses(const Skeleton& skeleton, const std::vector<TransformList>& poses) {
  ANIMSPACE_RETURN_IF_ERROR(check_poses(skeleton, poses));
  const int b = skeleton.bone_count();
  const double count = static_cast<double>(poses.size());

  AnimationSpaceMetrics metrics;
  metrics.P.setZero(4L * b, 4L * b);
  metrics.expected_joints.assign(static_cast<size_t>(b), Transform::Zero());
  std::vector<TransformList> joint_samples(static_cast<size_t>(b));
  Eigen::MatrixXd G(4, 4L * b);
  for (const TransformList& pose : poses) {
    for (int j = 0; j < b; ++j) G.middleCols<4>(4L * j) = pose[static_cast<size_t>(j)];
    metrics.P.noalias() += G.transpose() * G;
    const TransformList joints = joint_transforms(skeleton, pose);
    for (size_t j = 0; j < static_cast<size_t>(b); ++j) {
      metrics.expected_joints[j] += joints[j];
      joint_samples[j].push_back(joints[j]);
    }
  }
  metrics.P /= count;
  metrics.P = (0.5 * (metrics.P + metrics.P.transpose())).eval();
  metrics.joint_bounds.assign(static_cast<size_t>(b), JointBound{});
  for (size_t j = 0; j < static_cast<size_t>(b); ++j) {
    metrics.expected_joints[j] /= count;
    metrics.expected_joints[j].row(3) << 0, 0, 0, 1;
    if (j > 0) metrics.joint_bounds[j] = sample_bound(joint_samples[j]);
  }
  metrics.expected_joints[0].setIdentity();
  return metrics;
}

Status validate(const AnimationSpaceMetrics& metrics, int bone_count) {
  ANIMSPACE_RETURN_IF_ERROR(check_bone_count(metrics, bone_count));
  if (metrics.P.cols() != metrics.P.rows()) return invalid("metrics: P is not square");
  if (!metrics.P.allFinite()) return invalid("metrics: P has a NaN or infinite entry");
  const double scale = std::max(1.0, metrics.P.cwiseAbs().maxCoeff());
  const double asymmetry = (metrics.P - metrics.P.transpose()).cwiseAbs().maxCoeff();
  if (asymmetry > kSymmetryTolerance * scale) {
    return invalid("metrics: P is not symmetric (largest |P − Pᵀ| entry " + std::to_string(asymmetry) + ")");
  }
  for (int j = 0; j < bone_count; ++j) {
    if (!is_affine(metrics.expected_joints[static_cast<size_t>(j)])) {
      return invalid("metrics: E[L_j] of " + bone_label(j) + " is not a finite affine matrix");
    }
    const JointBound& bound = metrics.joint_bounds[static_cast<size_t>(j)];
    if (!(bound.linear_norm >= 0) || !std::isfinite(bound.linear_norm) || !(bound.translation_radius >= 0) ||
        !std::isfinite(bound.translation_radius) || !bound.translation_centre.allFinite()) {
      return invalid("metrics: bound of " + bone_label(j) +
                     " needs finite, non-negative linear norm and translation radius and a finite centre");
    }
  }
  return Status::Ok();
}

// -------------------------------------------------------------------------------------------
// Norms
// -------------------------------------------------------------------------------------------

SparseAnimationVector vertex_difference(const AnimationSpaceModel& model, int vertex_a, int vertex_b) {
  assert(vertex_a >= 0 && vertex_a < model.vertex_count() && vertex_b >= 0 && vertex_b < model.vertex_count());
  const InfluenceSets& influences = model.influences;
  SparseAnimationVector out;
  std::vector<Eigen::Vector4d> columns;
  int a = influences.begin(vertex_a), b = influences.begin(vertex_b);
  const int a_end = influences.end(vertex_a), b_end = influences.end(vertex_b);
  // Merge the two sorted influence lists.
  while (a < a_end || b < b_end) {
    const int bone_a = a < a_end ? influences.bones[static_cast<size_t>(a)] : model.bone_count();
    const int bone_b = b < b_end ? influences.bones[static_cast<size_t>(b)] : model.bone_count();
    Eigen::Vector4d column = Eigen::Vector4d::Zero();
    const int bone = std::min(bone_a, bone_b);
    if (bone_a == bone) column += model.positions.col(a++);
    if (bone_b == bone) column -= model.positions.col(b++);
    out.bones.push_back(bone);
    columns.push_back(column);
  }
  out.vectors.resize(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) out.vectors.col(static_cast<Eigen::Index>(k)) = columns[k];
  return out;
}

Result<double> l22_norm(const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s) {
  ANIMSPACE_RETURN_IF_ERROR(check_dense(metrics, s, "s"));
  return norm_from_square(s.dot(metrics.P * s));
}

Result<double> l22_norm(const AnimationSpaceMetrics& metrics, const SparseAnimationVector& s) {
  ANIMSPACE_RETURN_IF_ERROR(check_sparse(static_cast<int>(metrics.P.rows() / 4), s, "s"));
  return norm_from_square(sparse_form(metrics.P, s, s));
}

Result<double> l22_inner_product(const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s,
                                 const Eigen::VectorXd& t) {
  ANIMSPACE_RETURN_IF_ERROR(check_dense(metrics, s, "s"));
  ANIMSPACE_RETURN_IF_ERROR(check_dense(metrics, t, "t"));
  return s.dot(metrics.P * t);
}

Result<double> l22_inner_product(const AnimationSpaceMetrics& metrics, const SparseAnimationVector& s,
                                 const SparseAnimationVector& t) {
  const int b = static_cast<int>(metrics.P.rows() / 4);
  ANIMSPACE_RETURN_IF_ERROR(check_sparse(b, s, "s"));
  ANIMSPACE_RETURN_IF_ERROR(check_sparse(b, t, "t"));
  return sparse_form(metrics.P, s, t);
}

Result<Eigen::MatrixXd> normalised_animation_space_matrix(const Eigen::MatrixXd& P) {
  if (P.rows() != P.cols()) {
    return invalid("P is " + std::to_string(P.rows()) + " × " + std::to_string(P.cols()) + ", expected square");
  }
  if (!P.allFinite()) return invalid("P has a NaN or infinite entry");
  if (P.size() == 0) return Eigen::MatrixXd(0, 0);
  const double scale = std::max(1.0, P.cwiseAbs().maxCoeff());
  if ((P - P.transpose()).cwiseAbs().maxCoeff() > kSymmetryTolerance * scale) return invalid("P is not symmetric");
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(P);
  if (eigen.info() != Eigen::Success) {
    return make_error(ErrorCode::kInternal, "eigendecomposition of P did not converge");
  }
  Eigen::VectorXd values = eigen.eigenvalues();
  const double tolerance = kEigenvalueTolerance * std::max(values.maxCoeff(), 0.0);
  if (values.minCoeff() < -tolerance) {
    return invalid("P is not positive semi-definite: eigenvalue " + std::to_string(values.minCoeff()) +
                   " below −" + std::to_string(tolerance));
  }
  values = values.cwiseMax(0.0).cwiseSqrt();
  Eigen::MatrixXd C = eigen.eigenvectors() * values.asDiagonal() * eigen.eigenvectors().transpose();
  return Eigen::MatrixXd(0.5 * (C + C.transpose()));
}

Result<double> l2inf_norm(const Skeleton& skeleton, const AnimationSpaceMetrics& metrics, const Eigen::VectorXd& s) {
  ANIMSPACE_RETURN_IF_ERROR(check_bone_count(metrics, skeleton.bone_count()));
  ANIMSPACE_RETURN_IF_ERROR(check_dense(metrics, s, "s"));
  return SpherePropagation(skeleton, metrics.joint_bounds).norm(sparse_from_dense(s));
}

Result<double> l2inf_norm(const Skeleton& skeleton, const AnimationSpaceMetrics& metrics,
                          const SparseAnimationVector& s) {
  ANIMSPACE_RETURN_IF_ERROR(check_bone_count(metrics, skeleton.bone_count()));
  ANIMSPACE_RETURN_IF_ERROR(check_sparse(skeleton.bone_count(), s, "s"));
  return SpherePropagation(skeleton, metrics.joint_bounds).norm(s);
}

// -------------------------------------------------------------------------------------------
// Bounding sphere (§7.2)
// -------------------------------------------------------------------------------------------

Result<geometry::BoundingSphere> pose_bounding_sphere(const AnimationSpaceModel& model, const AnimationSpaceMetrics& metrics) {
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  ANIMSPACE_RETURN_IF_ERROR(check_bone_count(metrics, model.bone_count()));
  const int V = model.vertex_count();
  if (V == 0) return invalid("model has no vertices; a bounding sphere needs at least one");
  const size_t b = static_cast<size_t>(model.bone_count());

  // Centroid in animation space, bone by bone (weight 1 in total).
  std::vector<Eigen::Vector4d> centroid(b, Eigen::Vector4d::Zero());
  for (int k = 0; k < model.influences.influence_count(); ++k) {
    centroid[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] += model.positions.col(k);
  }
  // E[G_j] under uniform rotations and rest translations: E[L_j] = [0 L̲̂_j; 0 1], so
  // E[G_j] = E[G_φ(j)] E[L_j] (independent joints) and E[G_0] = I.
  const TransformList rest_joints = rest_joint_transforms(model.skeleton);
  TransformList expected_global(b, Transform::Identity());
  Eigen::Vector4d centre = centroid[0];
  for (size_t j = 1; j < b; ++j) {
    Transform expected_joint = Transform::Identity();
    expected_joint.topLeftCorner<3, 3>().setZero();
    expected_joint.topRightCorner<3, 1>() = rest_joints[j].topRightCorner<3, 1>();
    expected_global[j] = expected_global[static_cast<size_t>(model.skeleton.parents[j])] * expected_joint;
    centre += expected_global[j] * centroid[j];
  }
  geometry::BoundingSphere sphere;
  sphere.centre = centre.head<3>() / static_cast<double>(V);

  // Radius: max ‖p_i − c‖₂,∞ with c = (centre, 1) on bone 0, so p_i − c has weight 0.
  SpherePropagation propagation(model.skeleton, metrics.joint_bounds);
  const Eigen::Vector4d c(sphere.centre.x(), sphere.centre.y(), sphere.centre.z(), 1.0);
  SparseAnimationVector difference;
  for (int i = 0; i < V; ++i) {
    const int first = model.influences.begin(i), last = model.influences.end(i);
    const bool has_root = model.influences.bones[static_cast<size_t>(first)] == 0;
    const int count = last - first + (has_root ? 0 : 1);
    difference.bones.resize(static_cast<size_t>(count));
    difference.vectors.resize(4, count);
    int out = 0;
    if (!has_root) {
      difference.bones[0] = 0;
      difference.vectors.col(0) = -c;
      out = 1;
    }
    for (int k = first; k < last; ++k, ++out) {
      difference.bones[static_cast<size_t>(out)] = model.influences.bones[static_cast<size_t>(k)];
      difference.vectors.col(out) = model.positions.col(k);
    }
    if (has_root) difference.vectors.col(0) -= c;
    sphere.radius = std::max(sphere.radius, propagation.norm(difference));
  }
  return sphere;
}

// -------------------------------------------------------------------------------------------
// Transforming a model (§3.4)
// -------------------------------------------------------------------------------------------

Status scale_model(double scale, AnimationSpaceModel& model, AnimationSpaceMetrics& metrics) {
  if (!std::isfinite(scale) || !(scale > 0)) {
    return invalid("scale is " + std::to_string(scale) + ", expected a finite factor > 0");
  }
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  ANIMSPACE_RETURN_IF_ERROR(validate(metrics, model.bone_count()));
  const int b = model.bone_count();

  // eq. 3.29: p̄_j ← s p̄_j (tangents are differences of positions and scale alike).
  model.positions.topRows<3>() *= scale;
  if (model.has_tangents()) {
    model.tangent_s.topRows<3>() *= scale;
    model.tangent_t.topRows<3>() *= scale;
  }
  // eq. 3.30: G̲_j ← s G̲_j in every pose, the rest pose included, so L̲_j ← s L̲_j.
  for (Transform& rest : model.skeleton.rest) rest.topRightCorner<3, 1>() *= scale;
  for (Transform& expected : metrics.expected_joints) expected.topRightCorner<3, 1>() *= scale;
  for (JointBound& bound : metrics.joint_bounds) {
    bound.translation_centre *= scale;
    bound.translation_radius *= scale;
  }
  // eq. 3.31: [A B; C D] → [A sB; sC s²(D − 1) + 1] for every block E[G_iᵀG_j].
  for (int i = 0; i < b; ++i) {
    for (int j = 0; j < b; ++j) {
      auto block = metrics.P.block<4, 4>(4L * i, 4L * j);
      block.topRightCorner<3, 1>() *= scale;
      block.bottomLeftCorner<1, 3>() *= scale;
      block(3, 3) = scale * scale * (block(3, 3) - 1.0) + 1.0;
    }
  }
  return Status::Ok();
}

Status rigid_transform_model(const Transform& M, AnimationSpaceModel& model, AnimationSpaceMetrics& metrics) {
  if (!is_affine(M)) return invalid("M is not a finite affine transform (last row 0 0 0 1)");
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  const double orthonormality = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthonormality > kRotationTolerance || R.determinant() <= 0) {
    return invalid("M's linear part is not a rotation (|RᵀR − I| = " + std::to_string(orthonormality) +
                   ", det = " + std::to_string(R.determinant()) + "); scale with scale_model first");
  }
  ANIMSPACE_RETURN_IF_ERROR(validate(model));
  ANIMSPACE_RETURN_IF_ERROR(validate(metrics, model.bone_count()));
  const size_t b = static_cast<size_t>(model.bone_count());
  const Eigen::Vector3d t = M.topRightCorner<3, 1>();

  // eq. 3.32: p_0 ← M p_0; every non-root bone's G_j ← M G_j, the rest pose included.
  for (int k = 0; k < model.influences.influence_count(); ++k) {
    if (model.influences.bones[static_cast<size_t>(k)] != 0) continue;
    model.positions.col(k) = M * model.positions.col(k);
    if (model.has_tangents()) {
      model.tangent_s.col(k) = M * model.tangent_s.col(k);
      model.tangent_t.col(k) = M * model.tangent_t.col(k);
    }
  }
  for (size_t j = 1; j < b; ++j) model.skeleton.rest[j] = M * model.skeleton.rest[j];

  // Sub-root joints: L_j ← M L_j, so E[L_j] ← M E[L_j]; ‖R L̄‖₂ = ‖L̄‖₂ and the translation
  // sphere moves with M.
  for (size_t j = 1; j < b; ++j) {
    if (model.skeleton.parents[j] != 0) continue;
    metrics.expected_joints[j] = M * metrics.expected_joints[j];
    metrics.joint_bounds[j].translation_centre = R * metrics.joint_bounds[j].translation_centre + t;
  }

  // eq. 3.33 with MᵀM = [I B; Bᵀ C], B = Rᵀt, C − 1 = ‖t‖², and E[G_j] = E[G_0ᵀG_j] = P_0j
  // (read before any block changes).
  Eigen::MatrixXd& P = metrics.P;
  const Eigen::Vector3d B = R.transpose() * t;
  const double C_minus_1 = t.squaredNorm();
  TransformList expected_global(b);
  for (size_t j = 0; j < b; ++j) expected_global[j] = P.block<4, 4>(0, 4L * static_cast<Eigen::Index>(j));
  for (size_t i = 1; i < b; ++i) {
    const Eigen::Matrix3d Gi_linear = expected_global[i].topLeftCorner<3, 3>();
    const Eigen::Vector3d Gi_translation = expected_global[i].topRightCorner<3, 1>();
    for (size_t j = 1; j < b; ++j) {
      const Eigen::Matrix3d Gj_linear = expected_global[j].topLeftCorner<3, 3>();
      const Eigen::Vector3d Gj_translation = expected_global[j].topRightCorner<3, 1>();
      auto block = P.block<4, 4>(4L * static_cast<Eigen::Index>(i), 4L * static_cast<Eigen::Index>(j));
      block.topRightCorner<3, 1>() += Gi_linear.transpose() * B;
      block.bottomLeftCorner<1, 3>() += B.transpose() * Gj_linear;
      block(3, 3) += Gi_translation.dot(B) + B.dot(Gj_translation) + C_minus_1;
    }
  }
  // Root rows and columns: E[G_0'ᵀG_j'] = E[M G_j].
  for (size_t j = 1; j < b; ++j) {
    const Eigen::Matrix4d block = M * expected_global[j];
    P.block<4, 4>(0, 4L * static_cast<Eigen::Index>(j)) = block;
    P.block<4, 4>(4L * static_cast<Eigen::Index>(j), 0) = block.transpose();
  }
  return Status::Ok();
}

}  // namespace animspace::animation_space
