// Weighted Kabsch / Umeyama (no scale): R from the SVD of the cross-covariance of the centred
// point sets with Umeyama's (1991, eq. 39–40) sign correction, t from the centroids.
#include "core/geometry/rigid_fit.h"

#include <cassert>
#include <cmath>

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace animspace::geometry {
namespace {

using Eigen::Index;
using Eigen::Matrix3d;
using Eigen::Vector3d;

// A set whose RMS spread about its centroid is below this fraction of its RMS distance from the
// origin is one point up to rounding of its coordinates (double resolves ~2e-16 of them).
constexpr double kCoincidentTolerance = 1e-12;
// Cross-covariance with σ_2 below this fraction of σ_1: the points lie on a line up to rounding,
// and the twist about that line would be set by rounding noise rather than by the data.
constexpr double kCollinearTolerance = 1e-10;

// The proper rotation R maximising tr(Rᵀ M), which minimises Σ w‖R p + t − q‖² for the centred
// sets behind M = Σ w q pᵀ (Umeyama 1991). bound = sqrt(Σ w‖p‖² · Σ w‖q‖²) >= ‖M‖
// (Cauchy–Schwarz) sets the scale for "M is zero".
Matrix3d best_rotation(const Matrix3d& M, double bound) {
  const Eigen::JacobiSVD<Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Vector3d sigma = svd.singularValues();
  const Matrix3d& U = svd.matrixU();
  const Matrix3d& V = svd.matrixV();
  // Uncorrelated sets (M at rounding level): every rotation fits equally well.
  if (sigma(0) <= kCoincidentTolerance * bound) return Matrix3d::Identity();
  // M ≈ σ_1 u vᵀ: any R with R v = u is optimal; take the smallest such rotation.
  if (sigma(1) <= kCollinearTolerance * sigma(0)) {
    return Eigen::Quaterniond::FromTwoVectors(V.col(0), U.col(0)).toRotationMatrix();
  }
  // With rank M >= 2 the optimum is unique: U diag(1, 1, s) Vᵀ with s = det(U)·det(V), which
  // turns the reflection U Vᵀ (when det = -1) into the best proper rotation.
  const Vector3d signs(1.0, 1.0, U.determinant() * V.determinant() < 0.0 ? -1.0 : 1.0);
  return U * signs.asDiagonal() * V.transpose();
}

}  // namespace

RigidTransform RigidTransform::inverse() const {
  RigidTransform inverted;
  inverted.rotation = rotation.transpose();
  inverted.translation = -(inverted.rotation * translation);
  return inverted;
}

RigidTransform fit_rigid(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to) {
  return fit_rigid(from, to, Eigen::VectorXd::Ones(from.cols()));
}

RigidTransform fit_rigid(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to,
                         const Eigen::VectorXd& weights) {
  assert(from.cols() == to.cols() && weights.size() == from.cols());
  assert(weights.allFinite() && (weights.array() >= 0.0).all());
  const Index N = from.cols();

  // 1. Weighted centroids; zero-weight points are skipped, not multiplied by zero, so that they
  //    may hold anything.
  double total_weight = 0.0;
  Vector3d sum_from = Vector3d::Zero(), sum_to = Vector3d::Zero();
  for (Index i = 0; i < N; ++i) {
    const double w = weights(i);
    if (w == 0.0) continue;
    assert(from.col(i).allFinite() && to.col(i).allFinite());
    total_weight += w;
    sum_from += w * from.col(i);
    sum_to += w * to.col(i);
  }
  RigidTransform transform;
  if (!(total_weight > 0.0)) return transform;
  const Vector3d centroid_from = sum_from / total_weight;
  const Vector3d centroid_to = sum_to / total_weight;

  // 2. Cross-covariance M = Σ w (to_i − c_to)(from_i − c_from)ᵀ of the centred sets (second pass
  //    over centred points, not Σ w to fromᵀ − W c cᵀ, which cancels for sets far from the
  //    origin), with each set's spread and magnitude for the degeneracy tests.
  Matrix3d M = Matrix3d::Zero();
  double spread_from = 0.0, spread_to = 0.0, magnitude_from = 0.0, magnitude_to = 0.0;
  for (Index i = 0; i < N; ++i) {
    const double w = weights(i);
    if (w == 0.0) continue;
    const Vector3d p = from.col(i) - centroid_from;
    const Vector3d q = to.col(i) - centroid_to;
    M.noalias() += (w * q) * p.transpose();
    spread_from += w * p.squaredNorm();
    spread_to += w * q.squaredNorm();
    magnitude_from += w * from.col(i).squaredNorm();
    magnitude_to += w * to.col(i).squaredNorm();
  }

  // 3. Rotation.
  constexpr double kCoincident2 = kCoincidentTolerance * kCoincidentTolerance;
  const bool single_point =
      spread_from <= kCoincident2 * magnitude_from || spread_to <= kCoincident2 * magnitude_to;
  if (!single_point) transform.rotation = best_rotation(M, std::sqrt(spread_from * spread_to));
  transform.translation = centroid_to - transform.rotation * centroid_from;
  return transform;
}

void apply_rigid(const RigidTransform& transform, Eigen::Ref<Eigen::Matrix3Xd> points) {
  points = (transform.rotation * points).colwise() + transform.translation;
}

Eigen::VectorXd transform_frame(const RigidTransform& transform, const Eigen::VectorXd& frame_3n) {
  assert(frame_3n.size() % 3 == 0);
  const Index N = frame_3n.size() / 3;
  Eigen::VectorXd transformed(frame_3n.size());
  const Eigen::Map<const Eigen::Matrix3Xd> in(frame_3n.data(), 3, N);
  Eigen::Map<Eigen::Matrix3Xd> out(transformed.data(), 3, N);
  out.noalias() = transform.rotation * in;
  out.colwise() += transform.translation;
  return transformed;
}

}  // namespace animspace::geometry
