// A brute-force reference for min xᵀPx s.t. Ax = b (the least-norm minimiser), independent of
// core/lod's Appendix A.2 solver: parametrise Ax = b as x0 + Nz (x0 = A⁺b, N = null(A) by SVD),
// z* = −(NᵀPN)⁺ NᵀP x0 minimises (x0 + Nz)ᵀP(x0 + Nz); the minimisers are z* + null(NᵀPN), and
// the one of least ‖x‖ is x0 + Nz* with its component along N·null(NᵀPN) removed. Eigenvalues
// of NᵀPN at or below 1e-10 of P's largest count as zero.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace animspace::testing {

inline Eigen::VectorXd null_space_solution(const Eigen::MatrixXd& P, const Eigen::MatrixXd& A,
                                           const Eigen::VectorXd& b) {
  const Eigen::Index n = A.cols();
  const Eigen::Index m = A.rows();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::VectorXd x0 = svd.solve(b);
  if (m == n) return x0;  // a single feasible point
  const Eigen::MatrixXd N = svd.matrixV().rightCols(n - m);
  Eigen::MatrixXd M = N.transpose() * P * N;
  M = 0.5 * (M + M.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(M);
  const double p_max = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(P).eigenvalues().cwiseAbs().maxCoeff();
  const double threshold = 1e-10 * p_max;
  const Eigen::VectorXd g = N.transpose() * P * x0;
  Eigen::VectorXd z = Eigen::VectorXd::Zero(n - m);
  std::vector<Eigen::Index> flat;
  for (Eigen::Index i = 0; i < n - m; ++i) {
    const double lambda = eigen.eigenvalues()(i);
    const Eigen::VectorXd v = eigen.eigenvectors().col(i);
    if (lambda > threshold) {
      z -= v * (v.dot(g) / lambda);
    } else {
      flat.push_back(i);
    }
  }
  Eigen::VectorXd x = x0 + N * z;
  for (const Eigen::Index i : flat) {
    const Eigen::VectorXd direction = N * eigen.eigenvectors().col(i);  // orthonormal set
    x -= direction * direction.dot(x);
  }
  return x;
}

}  // namespace animspace::testing
