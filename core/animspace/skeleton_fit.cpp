// Merry 2007 §4.1.4: per-bone rigid motions from core vertices (eq. 4.5 + polar decomposition,
// as James & Twigg 2005) and rest joints that minimise the variance of the joint translations
// (eq. 4.6) with the λ (h_j − u_j) = 0 regulariser.
#include "core/animspace/skeleton_fit.h"

#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

#include "core/common/timing.h"

namespace animspace::animation_space {
namespace {

// Principal spreads (standard deviations) below this fraction of the largest count as zero: the
// affine fit leaves such directions out, and a bone whose second spread is below it has its core
// vertices on a line. Points arrive as float (relative precision 6e-8), so a direction this thin
// would otherwise amplify rounding by up to ~1e3.
constexpr double kRelativeSpread = 1e-4;

// Relative pivot below which, with λ = 0, a joint position counts as undetermined.
constexpr double kUndeterminedJoint = 1e-6;

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

Eigen::Matrix3Xd gather(const Eigen::Matrix3Xd& points, const std::vector<int32_t>& indices) {
  Eigen::Matrix3Xd out(3, static_cast<Eigen::Index>(indices.size()));
  for (size_t c = 0; c < indices.size(); ++c) out.col(static_cast<Eigen::Index>(c)) = points.col(indices[c]);
  return out;
}

// Row p of the n × 3V frame matrix as 3 × V doubles.
Eigen::Matrix3Xd example_points(const FrameMatrix& meshes, Eigen::Index p) {
  return Eigen::Map<const Eigen::Matrix<float, 3, Eigen::Dynamic>>(meshes.row(p).data(), 3, meshes.cols() / 3)
      .cast<double>();
}

// Eigenvalues (ascending) and eigenvectors of the centred scatter matrix of `points`.
Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> scatter(const Eigen::Matrix3Xd& points, Eigen::Vector3d& mean) {
  mean = points.rowwise().mean();
  const Eigen::Matrix3Xd centred = points.colwise() - mean;
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(centred * centred.transpose());
}

Status check_inputs(const PointMatrix& reference_points, const FrameMatrix& meshes, const Skeleton& user_skeleton,
                    const std::vector<std::vector<int32_t>>& core_vertices, const SkeletonFitOptions& options) {
  ANIMSPACE_RETURN_IF_ERROR(validate(user_skeleton));
  const Eigen::Index V = reference_points.rows();
  if (!reference_points.allFinite()) return invalid("fit_skeleton: reference points contain a NaN or infinite coordinate");
  if (meshes.rows() < 1) return invalid("fit_skeleton: no example meshes; expected at least one");
  if (meshes.cols() != 3 * V) {
    return invalid("fit_skeleton: example meshes have " + std::to_string(meshes.cols()) + " columns, expected " +
                   std::to_string(3 * V) + " (3 × the reference's " + std::to_string(V) + " vertices)");
  }
  if (!meshes.allFinite()) return invalid("fit_skeleton: example meshes contain a NaN or infinite coordinate");
  const int b = user_skeleton.bone_count();
  if (static_cast<int>(core_vertices.size()) != b) {
    return invalid("fit_skeleton: " + std::to_string(core_vertices.size()) + " core vertex lists for " +
                   std::to_string(b) + " bones; expected one per bone");
  }
  if (!core_vertices[0].empty()) {
    return invalid("fit_skeleton: bone 0 has core vertices; the root is fixed (G_0 = I, Merry 2007 §2.1), its list "
                   "must be empty");
  }
  for (int j = 0; j < b; ++j) {
    for (int32_t index : core_vertices[static_cast<size_t>(j)]) {
      if (index < 0 || index >= V) {
        return invalid("fit_skeleton: core vertex " + std::to_string(index) + " of bone " + std::to_string(j) +
                       " is outside 0 … " + std::to_string(V - 1));
      }
    }
  }
  if (!(options.joint_regularisation >= 0) || !std::isfinite(options.joint_regularisation)) {
    return invalid("fit_skeleton: joint_regularisation must be finite and ≥ 0");
  }
  return Status::Ok();
}

}  // namespace

bool determines_rigid_motion(const Eigen::Matrix3Xd& points) {
  if (points.cols() < 3) return false;
  Eigen::Vector3d mean;
  const Eigen::Vector3d eigenvalues = scatter(points, mean).eigenvalues().cwiseMax(0.0);
  return eigenvalues(2) > 0 && std::sqrt(eigenvalues(1)) >= kRelativeSpread * std::sqrt(eigenvalues(2));
}

Transform fit_rigid_motion(const Eigen::Matrix3Xd& rest, const Eigen::Matrix3Xd& posed, bool* reflection_fixed) {
  assert(rest.cols() == posed.cols() && rest.cols() >= 1);
  // Eq. 4.5 with the translation eliminated: the linear part M̄ solves M̄ S_rr = S_pr, S_rr the
  // rest scatter and S_pr the posed–rest cross scatter. The pseudo-inverse of S_rr drops the
  // directions the rest points do not span (the normal of a coplanar set).
  Eigen::Vector3d rest_mean;
  const auto eigen = scatter(rest, rest_mean);
  const Eigen::Vector3d posed_mean = posed.rowwise().mean();
  const Eigen::Matrix3d cross = (posed.colwise() - posed_mean) * (rest.colwise() - rest_mean).transpose();
  const double largest = eigen.eigenvalues()(2);
  Eigen::Matrix3d pseudo_inverse = Eigen::Matrix3d::Zero();
  for (int l = 0; l < 3; ++l) {
    const double value = eigen.eigenvalues()(l);
    if (value > 0 && value >= kRelativeSpread * kRelativeSpread * largest) {
      pseudo_inverse += eigen.eigenvectors().col(l) * eigen.eigenvectors().col(l).transpose() / value;
    }
  }
  const Eigen::Matrix3d linear = cross * pseudo_inverse;
  // Polar decomposition M̄ = R S from the SVD M̄ = U Σ Vᵀ: R = U Vᵀ, S = V Σ Vᵀ. If R is a
  // reflection, negating S's smallest eigenvalue (the last singular value) gives
  // R = U diag(1, 1, −1) Vᵀ, the nearest rotation.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(linear, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  const bool reflection = rotation.determinant() < 0;
  if (reflection) {
    Eigen::Matrix3d U = svd.matrixU();
    U.col(2) = -U.col(2);
    rotation = U * svd.matrixV().transpose();
  }
  if (reflection_fixed) *reflection_fixed = reflection;
  // With R fixed, the least-squares translation maps the rest centroid onto the posed one.
  return make_transform(rotation, posed_mean - rotation * rest_mean);
}

Result<Skeleton> skeleton_from_motions(const Skeleton& user_skeleton, const std::vector<TransformList>& motions,
                                       double joint_regularisation, std::vector<double>* joint_spread) {
  const int b = user_skeleton.bone_count();
  const int n = static_cast<int>(motions.size());
  if (joint_spread) joint_spread->assign(static_cast<size_t>(b), 0.0);
  // Rest joints h_j (eq. 4.6), down the tree: with N^p = (M^p_φ)⁻¹ M^p_j = [A^p | t^p],
  //    L̲_j^p = A^p h_j + t^p − h_φ; minimise Σ_p ‖L̲_j^p − m_j‖² + λ² ‖h_j − u_j‖² over (h_j, m_j),
  //    i.e. the rows [A^p  −I] (h, m) = h_φ − t^p and [λI  0] (h, m) = λ u_j.
  const double lambda = joint_regularisation;
  std::vector<Eigen::Vector3d> joints(static_cast<size_t>(b), Eigen::Vector3d::Zero());
  for (int j = 1; j < b; ++j) {
    const size_t parent = static_cast<size_t>(user_skeleton.parents[static_cast<size_t>(j)]);
    const Eigen::Vector3d u = user_skeleton.rest[static_cast<size_t>(j)].topRightCorner<3, 1>();
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3L * n + 3, 6);
    Eigen::VectorXd rhs(3L * n + 3);
    std::vector<Transform, Eigen::aligned_allocator<Transform>> relative(static_cast<size_t>(n));
    for (int p = 0; p < n; ++p) {
      const TransformList& M = motions[static_cast<size_t>(p)];
      relative[static_cast<size_t>(p)] = affine_inverse(M[parent]) * M[static_cast<size_t>(j)];
      A.block<3, 3>(3L * p, 0) = relative[static_cast<size_t>(p)].topLeftCorner<3, 3>();
      A.block<3, 3>(3L * p, 3) = -Eigen::Matrix3d::Identity();
      rhs.segment<3>(3L * p) = joints[parent] - relative[static_cast<size_t>(p)].topRightCorner<3, 1>();
    }
    A.block<3, 3>(3L * n, 0) = lambda * Eigen::Matrix3d::Identity();
    rhs.segment<3>(3L * n) = lambda * u;
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    // Without the regulariser a hinge's axis is a null direction, but fitted rotations carry
    // float-level noise, so rank is judged with a tolerance well above that noise (the pivots of
    // a column-pivoting QR decrease along R's diagonal).
    const double smallest_pivot = std::abs(qr.matrixR()(5, 5)), largest_pivot = std::abs(qr.matrixR()(0, 0));
    if (lambda == 0 && !(smallest_pivot > kUndeterminedJoint * largest_pivot)) {
      return make_error(ErrorCode::kFailedPrecondition,
                        "skeleton_from_motions: the joint of bone " + std::to_string(j) +
                            " is not determined by its motion (e.g. a hinge axis); set joint_regularisation > 0");
    }
    const Eigen::VectorXd x = qr.solve(rhs);
    joints[static_cast<size_t>(j)] = x.head<3>();
    const Eigen::Vector3d mean = x.tail<3>();
    double squared = 0;
    for (int p = 0; p < n; ++p) {
      const Transform& N = relative[static_cast<size_t>(p)];
      squared += (N.topLeftCorner<3, 3>() * x.head<3>() + N.topRightCorner<3, 1>() - joints[parent] - mean).squaredNorm();
    }
    if (joint_spread) (*joint_spread)[static_cast<size_t>(j)] = std::sqrt(squared / n);
  }

  Skeleton skeleton;
  skeleton.parents = user_skeleton.parents;
  skeleton.names = user_skeleton.names;
  skeleton.rest.resize(static_cast<size_t>(b));
  for (int j = 0; j < b; ++j) {
    skeleton.rest[static_cast<size_t>(j)] = make_transform(Eigen::Matrix3d::Identity(), joints[static_cast<size_t>(j)]);
  }
  return skeleton;
}

Result<FittedSkeleton> fit_skeleton(const PointMatrix& reference_points, const FrameMatrix& meshes,
                                    const Skeleton& user_skeleton,
                                    const std::vector<std::vector<int32_t>>& core_vertices,
                                    const SkeletonFitOptions& options, SkeletonFitReport* report) {
  const auto start = std::chrono::steady_clock::now();
  ANIMSPACE_RETURN_IF_ERROR(check_inputs(reference_points, meshes, user_skeleton, core_vertices, options));
  SkeletonFitReport local;
  SkeletonFitReport& out = report ? *report : local;
  const int b = user_skeleton.bone_count();
  const int n = static_cast<int>(meshes.rows());
  out = SkeletonFitReport{};
  out.rigid_rms.assign(static_cast<size_t>(b), 0.0);
  out.joint_spread.assign(static_cast<size_t>(b), 0.0);

  const Eigen::Matrix3Xd reference = reference_points.transpose().cast<double>();
  std::vector<Eigen::Matrix3Xd> examples;
  examples.reserve(static_cast<size_t>(n));
  for (int p = 0; p < n; ++p) examples.push_back(example_points(meshes, p));

  // 1. Rigid motion of every bone in every example (eq. 4.5, polar decomposition, translation
  //    refit). Parents precede children, so an inherited motion is already known.
  FittedSkeleton fitted;
  fitted.motions.assign(static_cast<size_t>(n), TransformList(static_cast<size_t>(b), Transform::Identity()));
  for (int j = 1; j < b; ++j) {
    const auto& indices = core_vertices[static_cast<size_t>(j)];
    const Eigen::Matrix3Xd rest = gather(reference, indices);
    if (!determines_rigid_motion(rest)) {
      if (!options.inherit_undetermined_bones) {
        return invalid("fit_skeleton: the " + std::to_string(indices.size()) + " core vertices of bone " +
                       std::to_string(j) +
                       " do not determine a rigid motion (need at least 3 not on one line); add core vertices or set "
                       "inherit_undetermined_bones");
      }
      const size_t parent = static_cast<size_t>(user_skeleton.parents[static_cast<size_t>(j)]);
      for (int p = 0; p < n; ++p) fitted.motions[static_cast<size_t>(p)][static_cast<size_t>(j)] = fitted.motions[static_cast<size_t>(p)][parent];
      out.inherited_bones.push_back(j);
      continue;
    }
    double squared = 0;
    for (int p = 0; p < n; ++p) {
      const Eigen::Matrix3Xd posed = gather(examples[static_cast<size_t>(p)], indices);
      bool reflection = false;
      const Transform M = fit_rigid_motion(rest, posed, &reflection);
      out.reflections_fixed += reflection ? 1 : 0;
      squared += ((M.topLeftCorner<3, 3>() * rest).colwise() + M.topRightCorner<3, 1>() - posed).squaredNorm();
      fitted.motions[static_cast<size_t>(p)][static_cast<size_t>(j)] = M;
    }
    out.rigid_rms[static_cast<size_t>(j)] = std::sqrt(squared / (static_cast<double>(n) * static_cast<double>(rest.cols())));
  }

  // 2. Rest joints h_j (eq. 4.6) and the skeleton (Ĝ_j = translation h_j).
  auto skeleton = skeleton_from_motions(user_skeleton, fitted.motions, options.joint_regularisation, &out.joint_spread);
  if (!skeleton) return skeleton.error();
  fitted.skeleton = std::move(*skeleton);

  // 3. The poses G^p_j = M^p_j Ĝ_j.
  fitted.poses.resize(static_cast<size_t>(n));
  for (int p = 0; p < n; ++p) {
    TransformList& G = fitted.poses[static_cast<size_t>(p)];
    G.resize(static_cast<size_t>(b));
    for (int j = 0; j < b; ++j) {
      G[static_cast<size_t>(j)] = fitted.motions[static_cast<size_t>(p)][static_cast<size_t>(j)] * fitted.skeleton.rest[static_cast<size_t>(j)];
    }
  }
  out.seconds = seconds_since(start);
  return fitted;
}

}  // namespace animspace::animation_space
