// Least-squares rigid motion between corresponding point sets (Kabsch 1976; Umeyama 1991
// without the scale), and its application to frames stored as point-major columns.
//
// Users: PMSC's frame alignment (a training frame whose character also moves as a whole carries
// that rigid motion in every point; expressing frames in a common rigid frame before the subspace
// analysis, Meyer & Anderson 2006 §3, keeps the basis for the deformation) and the segmentation
// of animation-space fitting (the rigid motion of each candidate part, Merry 2007 §4.1.4).
// Skeleton fitting keeps §4.1.4's own recipe (affine fit, then polar decomposition;
// animspace/skeleton_fit.h), which the thesis specifies and which is not a Kabsch fit.
//
// Precision: double. These run at training time, where accuracy matters more than speed.
#pragma once

#include <Eigen/Core>

namespace animspace::geometry {

// x_to = rotation · x_from + translation; rotation is proper (RᵀR = I, det R = +1).
struct RigidTransform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d apply(const Eigen::Vector3d& x_from) const {
    return rotation * x_from + translation;
  }
  // x_from = Rᵀ (x_to − t): [Rᵀ | −Rᵀt].
  RigidTransform inverse() const;
};

// The proper rigid motion minimising Σ_i ‖R from_i + t − to_i‖². from and to are 3 × N
// (column i of each is one correspondence), finite. When the best orthogonal matrix would be a
// reflection (e.g. to is a mirror image of from), the best proper rotation is returned instead
// (Umeyama's sign correction).
//
// Degenerate inputs still return a finite proper rotation:
//   - N = 0, or either set a single point up to rounding (all points coincident): R = I,
//     t = centroid(to) − centroid(from);
//   - points on a line (either set collinear up to rounding): the twist about the line is not
//     determined by the data; R is the smallest rotation taking the from line's direction to
//     the to line's (a 180° turn about an axis perpendicular to the line when they are opposite),
//     and t maps centroid to centroid;
//   - sets whose cross-covariance vanishes (no rotation fits better than another): R = I.
RigidTransform fit_rigid(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to);

// As above minimising Σ_i w_i ‖R from_i + t − to_i‖² with weights (N, finite, >= 0). Points of
// zero weight are skipped entirely (they may hold any value). All weights zero behaves as N = 0:
// the identity.
RigidTransform fit_rigid(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to,
                         const Eigen::VectorXd& weights);

// Applies the transform to every column of points (3 × N) in place.
void apply_rigid(const RigidTransform& transform, Eigen::Ref<Eigen::Matrix3Xd> points);

// A frame stored as one column of a training matrix, 3N values x0 y0 z0 x1 y1 z1 … (the
// point-major layout of pca.h with 3 channels), transformed point by point; returns 3N values.
Eigen::VectorXd transform_frame(const RigidTransform& transform, const Eigen::VectorXd& frame_3n);

}  // namespace animspace::geometry
