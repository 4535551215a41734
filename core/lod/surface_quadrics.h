// Quadric error memory in normalised animation space (issue #26): Garland & Heckbert's quadrics
// (1997; the n-dimensional form of their 1998 paper) under the L2,2 metric.
//
// Why this space: with y = C p and C = P^½ (Merry 2007 §3.3.2), ‖y − y'‖² = E‖G p − G p'‖² over
// the pose distribution P describes, so a triangle of the animation-space surface is a flat
// 2-dimensional triangle in R^{4b}, and the squared distance from y to its plane is the mean
// squared distance, across poses, from the posed point to the posed plane point with the same
// barycentric coordinates. Summing these planes over the original faces around a vertex (area
// weighted) and adding the sums as vertices merge gives every collapse the memory of the
// original surface that §6.2.1's memoryless cost lacks: its cost is how far, across poses, the
// merged vertex lies from every original face it now stands for.
//
// A plane's quadric is Q_f(y) = w_f (‖d‖² − (e₁·d)² − (e₂·d)²), d = y − a_f, with (e₁, e₂) an
// orthonormal basis of the face's plane and a_f a corner. A boundary edge adds the line through
// it (e₂ = 0), weighted by its squared length, so that boundaries remember where they were too.
// The quadrics are kept as lists of planes rather than dense 4b × 4b matrices: the lists of all
// live vertices hold 3F + 2·(boundary edges) planes in total whatever has merged, which for b
// bones is far less memory than V dense matrices (cow-rig: 64-dimensional y, 11 666 vertices).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"

namespace animspace::lod {

class SurfaceQuadrics {
 public:
  // One quadric per vertex from the faces around it. `Y` holds the vertices' normalised
  // positions (n × V, y = C p); `faces` index its columns (asserted in range). A degenerate face
  // (zero area) contributes nothing; each boundary edge (an edge of one face) adds its line.
  SurfaceQuadrics(const Eigen::MatrixXd& Y, const FaceMatrix& faces);

  // Q_v(y): the weighted sum of squared distances from y to vertex v's planes (≥ 0, model
  // units⁴: area × distance²).
  double error(int v, const Eigen::Ref<const Eigen::VectorXd>& y) const;

  // Σ of the weights of v's planes (model units²): error / weight is a mean squared distance.
  double weight(int v) const { return weights_[static_cast<size_t>(v)]; }

  // Vertex `from` merges into `into` (a collapse from → into): into's quadric becomes the sum
  // and from's is emptied.
  void merge(int from, int into);

  int plane_count(int v) const { return static_cast<int>(planes_[static_cast<size_t>(v)].size()); }

 private:
  Eigen::MatrixXd origin_;  // n × planes, a_f
  Eigen::MatrixXd e1_;      // n × planes
  Eigen::MatrixXd e2_;      // n × planes (zero for a boundary line)
  std::vector<double> plane_weight_;
  std::vector<std::vector<int32_t>> planes_;  // per vertex, the planes of its quadric
  std::vector<double> weights_;               // per vertex, Σ w
};

}  // namespace animspace::lod
