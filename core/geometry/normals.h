// Area-weighted vertex normals.
//
// The unnormalised cross product (v1 − v0) × (v2 − v0) of a face is twice its area along its
// normal, so summing them over a vertex's faces weights each face by its area. The core derives
// normals rather than keeping a file's (Merry 2007 §3.5); users: tangent planes for animation-
// space normals (animspace/tangents.h) and the renderer, for scenes that bring none.
#pragma once

#include <cassert>

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross

#include "core/common/types.h"

namespace animspace::geometry {

// normalise(Σ over incident faces of (v1 − v0) × (v2 − v0)) per vertex, faces counter-clockwise
// seen from outside. V is #V by 3 (float or double; the result has V's scalar, accumulated in
// it), F is #F by 3 with indices in [0, #V) (asserted). Vertices in no non-degenerate face get a
// zero row.
template <typename Derived>
Eigen::Matrix<typename Derived::Scalar, Eigen::Dynamic, 3, Eigen::RowMajor> area_weighted_normals(
    const Eigen::MatrixBase<Derived>& V, const FaceMatrix& F) {
  using Scalar = typename Derived::Scalar;
  using Vector3 = Eigen::Matrix<Scalar, 3, 1>;
  Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor> normals =
      Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor>::Zero(V.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int c = 0; c < 3; ++c) assert(F(f, c) >= 0 && F(f, c) < V.rows());
    const Vector3 v0 = V.row(F(f, 0)).transpose(), v1 = V.row(F(f, 1)).transpose(), v2 = V.row(F(f, 2)).transpose();
    const Vector3 n = (v1 - v0).cross(v2 - v0);
    for (int c = 0; c < 3; ++c) normals.row(F(f, c)) += n.transpose();
  }
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    const Scalar length = normals.row(i).norm();
    if (length > 0) normals.row(i) /= length;
  }
  return normals;
}

}  // namespace animspace::geometry
