// Reproducible random matrices for numerical tests.
#pragma once

#include <cstdint>
#include <random>

#include <Eigen/Dense>

namespace animspace::testing {

// rows × cols with independent standard normal entries, fixed by `seed`.
inline Eigen::MatrixXd gaussian_matrix(Eigen::Index rows, Eigen::Index cols, uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index j = 0; j < cols; ++j) {
    for (Eigen::Index i = 0; i < rows; ++i) m(i, j) = normal(engine);
  }
  return m;
}

// rows × cols with orthonormal columns (the thin Q of a Gaussian matrix).
inline Eigen::MatrixXd random_orthonormal(Eigen::Index rows, Eigen::Index cols, uint64_t seed) {
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(gaussian_matrix(rows, cols, seed));
  return qr.householderQ() * Eigen::MatrixXd::Identity(rows, cols);
}

}  // namespace animspace::testing
