#include "core/pmsc/regions.h"

#include <algorithm>
#include <cassert>
#include <limits>
#include <random>

namespace animspace::pmsc {

Eigen::MatrixXd motion_signatures(const Eigen::MatrixXd& basis, const Eigen::VectorXd& singular_values, int channels) {
  assert(basis.cols() == singular_values.size() && channels >= 1);
  const long D = channels;
  const long N = basis.rows() / D;
  const long M = basis.cols();
  Eigen::MatrixXd features(N, D * M);
  for (long i = 0; i < N; ++i) {
    for (long d = 0; d < D; ++d) {
      features.block(i, d * M, 1, M) = basis.row(i * D + d).cwiseProduct(singular_values.transpose());
    }
  }
  return features;
}

Regions cluster_regions(const Eigen::MatrixXd& basis, const Eigen::VectorXd& singular_values, int channels,
                        const std::vector<int>& key_points, int region_count, uint32_t seed) {
  assert(basis.cols() == singular_values.size());
  const long D = channels;
  const long N = basis.rows() / D;
  const long M = basis.cols();
  Regions out;
  if (region_count < 1 || N == 0 || key_points.empty()) return out;
  const long k = std::min<long>(region_count, N);

  const Eigen::MatrixXd features = motion_signatures(basis, singular_values, channels);

  // k-means++ seeding.
  std::mt19937 rng(seed);
  Eigen::MatrixXd centroids(k, D * M);
  centroids.row(0) = features.row(std::uniform_int_distribution<long>(0, N - 1)(rng));
  Eigen::VectorXd nearest = (features.rowwise() - centroids.row(0)).rowwise().squaredNorm();
  for (long c = 1; c < k; ++c) {
    const double total = nearest.sum();
    long pick = 0;
    if (total > 0) {
      double target = std::uniform_real_distribution<double>(0, total)(rng);
      while (pick < N - 1 && target > nearest(pick)) target -= nearest(pick++);
    }
    centroids.row(c) = features.row(pick);
    nearest = nearest.cwiseMin((features.rowwise() - centroids.row(c)).rowwise().squaredNorm());
  }

  // Lloyd iterations; distances through ‖f‖² − 2 f·c + ‖c‖² so the bulk is one matrix product.
  std::vector<int> assignment(static_cast<size_t>(N), 0);
  const Eigen::VectorXd feature_norms = features.rowwise().squaredNorm();
  for (int iteration = 0; iteration < 50; ++iteration) {
    Eigen::MatrixXd distances = -2.0 * features * centroids.transpose();
    distances.colwise() += feature_norms;
    distances.rowwise() += centroids.rowwise().squaredNorm().transpose();
    bool changed = false;
    for (long i = 0; i < N; ++i) {
      long best = 0;
      distances.row(i).minCoeff(&best);
      if (assignment[static_cast<size_t>(i)] != best) {
        assignment[static_cast<size_t>(i)] = static_cast<int>(best);
        changed = true;
      }
    }
    if (!changed && iteration > 0) break;
    Eigen::MatrixXd sums = Eigen::MatrixXd::Zero(k, D * M);
    Eigen::VectorXd counts = Eigen::VectorXd::Zero(k);
    for (long i = 0; i < N; ++i) {
      sums.row(assignment[static_cast<size_t>(i)]) += features.row(i);
      counts(assignment[static_cast<size_t>(i)]) += 1;
    }
    for (long c = 0; c < k; ++c) {
      if (counts(c) > 0) centroids.row(c) = sums.row(c) / counts(c);
    }
  }

  // Merge regions without key points into the nearest region with one, then renumber densely.
  std::vector<char> has_key(static_cast<size_t>(k), 0);
  for (int key : key_points) has_key[static_cast<size_t>(assignment[static_cast<size_t>(key)])] = 1;
  std::vector<int> target(static_cast<size_t>(k));
  for (long c = 0; c < k; ++c) {
    if (has_key[static_cast<size_t>(c)]) {
      target[static_cast<size_t>(c)] = static_cast<int>(c);
      continue;
    }
    double best = std::numeric_limits<double>::infinity();
    for (long other = 0; other < k; ++other) {
      if (!has_key[static_cast<size_t>(other)]) continue;
      const double distance = (centroids.row(c) - centroids.row(other)).squaredNorm();
      if (distance < best) {
        best = distance;
        target[static_cast<size_t>(c)] = static_cast<int>(other);
      }
    }
  }
  std::vector<int> dense(static_cast<size_t>(k), -1);
  for (long c = 0; c < k; ++c) {
    if (has_key[static_cast<size_t>(c)]) dense[static_cast<size_t>(c)] = out.count++;
  }
  out.point_regions.resize(static_cast<size_t>(N));
  for (long i = 0; i < N; ++i) {
    out.point_regions[static_cast<size_t>(i)] =
        dense[static_cast<size_t>(target[static_cast<size_t>(assignment[static_cast<size_t>(i)])])];
  }
  for (int key : key_points) out.key_regions.push_back(out.point_regions[static_cast<size_t>(key)]);
  return out;
}

}  // namespace animspace::pmsc
