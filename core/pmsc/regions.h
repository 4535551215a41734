// Regions for local fail-through (both seeds' future work, built here and measured in the
// benchmark): points that move together share a region, and each region's key points give its
// own RMS key-point error, so a caller can run the full calculation only where it is needed.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace animspace::pmsc {

struct Regions {
  int count = 0;
  std::vector<int> point_regions;  // N
  std::vector<int> key_regions;    // K
};

// The motion signature of each point: the D × M block of its basis rows scaled by the singular
// values, flattened to one row (N × D·M) — how the point moves along each subspace direction.
// basis: R × M (R = N·D); singular_values: M.
Eigen::MatrixXd motion_signatures(const Eigen::MatrixXd& basis, const Eigen::VectorXd& singular_values, int channels);

// k-means (k-means++ seeding, fixed seed: deterministic) of the points' motion signatures — the
// D × M block of basis rows of each point scaled by the singular values, i.e. how the point moves
// along each subspace direction. Euclidean distance between signatures is invariant to rotating
// the basis, so Varimax would not change the clusters. Regions left without a key point are
// merged into the nearest region that has one (its error could not be measured otherwise).
// basis: R × M (R = N·D); singular_values: M; key_points index the same N points.
Regions cluster_regions(const Eigen::MatrixXd& basis, const Eigen::VectorXd& singular_values, int channels,
                        const std::vector<int>& key_points, int region_count, uint32_t seed = 1);

}  // namespace animspace::pmsc
