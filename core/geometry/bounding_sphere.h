// A bounding sphere of a point set: centred on the axis-aligned bounding box, radius to the
// farthest point.
//
// Not the minimal sphere (Welzl's), but one pass, deterministic and within √3 of it; it is what
// frames a thumbnail (render/camera.h) and what eq. 7.2 of Merry 2007 measures depth to when a
// model stores no pose-space sphere (§7.2's pose_bounding_sphere, animspace/metrics.h, bounds
// every pose and is preferred where it exists).
#pragma once

#include <cmath>

#include <Eigen/Core>

namespace animspace::geometry {

struct BoundingSphere {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // model space
  double radius = 0;                                 // model units, ≥ 0
};

// The sphere of `points` (#V by 3, float or double, finite — asserted in debug builds): centre
// of the bounding box, radius the largest distance from it (0 for one point). No points give the
// zero sphere at the origin.
template <typename Derived>
BoundingSphere bounding_sphere(const Eigen::MatrixBase<Derived>& points) {
  BoundingSphere sphere;
  if (points.rows() == 0) return sphere;
  const auto as_double = points.template cast<double>();
  sphere.centre = (as_double.colwise().minCoeff() + as_double.colwise().maxCoeff()).transpose() / 2;
  sphere.radius = std::sqrt((as_double.rowwise() - sphere.centre.transpose()).rowwise().squaredNorm().maxCoeff());
  return sphere;
}

}  // namespace animspace::geometry
