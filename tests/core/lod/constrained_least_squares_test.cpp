// Tests of the constrained least-squares solver (Merry 2007 Appendix A.2).
//
// References are computed here by other means: the KKT system of the Lagrangian for a positive
// definite P, and for a singular P a brute-force null-space method (parametrise Ax = b as
// x0 + Nz, minimise over z with a pseudo-inverse, then take the least-norm minimiser).
#include "core/lod/constrained_least_squares.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "tests/support/constrained_least_squares_reference.h"

namespace animspace::lod {
namespace {

using Eigen::MatrixXd;
using testing::null_space_solution;
using Eigen::VectorXd;

MatrixXd gaussian(Eigen::Index rows, Eigen::Index cols, std::mt19937_64& engine) {
  std::normal_distribution<double> normal;
  MatrixXd M(rows, cols);
  for (Eigen::Index j = 0; j < cols; ++j) {
    for (Eigen::Index i = 0; i < rows; ++i) M(i, j) = normal(engine);
  }
  return M;
}

VectorXd gaussian(Eigen::Index size, std::mt19937_64& engine) { return gaussian(size, 1, engine); }

// P = BᵀB with B rank × n: symmetric, non-negative definite, rank `rank` (almost surely).
MatrixXd random_psd(Eigen::Index n, Eigen::Index rank, std::mt19937_64& engine) {
  const MatrixXd B = gaussian(rank, n, engine);
  return B.transpose() * B;
}

// The KKT conditions of min xᵀPx s.t. Ax = b: [2P Aᵀ; A 0] (x, μ) = (0, b), by dense LU. Unique
// for a positive definite P and a full-row-rank A.
VectorXd kkt_solution(const MatrixXd& P, const MatrixXd& A, const VectorXd& b) {
  const Eigen::Index n = P.rows();
  const Eigen::Index m = A.rows();
  MatrixXd M = MatrixXd::Zero(n + m, n + m);
  M.topLeftCorner(n, n) = 2 * P;
  M.topRightCorner(n, m) = A.transpose();
  M.bottomLeftCorner(m, n) = A;
  VectorXd rhs = VectorXd::Zero(n + m);
  rhs.tail(m) = b;
  return Eigen::FullPivLU<MatrixXd>(M).solve(rhs).head(n);
}

double objective(const MatrixXd& P, const VectorXd& x) { return x.dot(P * x); }

// The solver against the brute force: same objective, same norm, same x.
void expect_matches_brute_force(const MatrixXd& P, const MatrixXd& A, const VectorXd& b) {
  const Result<VectorXd> x = constrained_least_squares(P, A, b);
  ASSERT_TRUE(x.ok()) << x.error().message;
  const VectorXd reference = null_space_solution(P, A, b);
  const double scale = std::max(1.0, reference.norm());
  EXPECT_LE((A * *x - b).norm(), 1e-10 * std::max(1.0, b.norm()));
  const double f = objective(P, *x);
  const double f_reference = objective(P, reference);
  EXPECT_NEAR(f, f_reference, 1e-9 * std::max(1.0, std::abs(f_reference)));
  EXPECT_NEAR(x->norm(), reference.norm(), 1e-8 * scale);
  EXPECT_LE((*x - reference).norm(), 1e-8 * scale) << "x = " << x->transpose() << "\nref = " << reference.transpose();
}

TEST(ConstrainedLeastSquares, PositiveDefiniteMatchesKktSystem) {
  std::mt19937_64 engine(11);
  const std::vector<std::pair<int, int>> shapes = {{1, 1}, {3, 1}, {4, 2}, {6, 2}, {8, 5}, {10, 3}, {7, 7}};
  for (const auto& [n, m] : shapes) {
    for (int trial = 0; trial < 3; ++trial) {
      const MatrixXd P = random_psd(n, n, engine) + 0.1 * MatrixXd::Identity(n, n);
      const MatrixXd A = gaussian(m, n, engine);
      const VectorXd b = gaussian(m, engine);
      const Result<VectorXd> x = constrained_least_squares(P, A, b);
      ASSERT_TRUE(x.ok()) << x.error().message;
      const VectorXd reference = kkt_solution(P, A, b);
      EXPECT_LE((*x - reference).norm(), 1e-9 * std::max(1.0, reference.norm())) << "n = " << n << ", m = " << m;
      EXPECT_LE((A * *x - b).norm(), 1e-10 * std::max(1.0, b.norm()));
    }
  }
}

TEST(ConstrainedLeastSquares, IdentityWeightIsMinimumNormSolution) {
  // A.2.1 alone: P = I gives x = Aᵀ(AAᵀ)⁻¹b.
  std::mt19937_64 engine(12);
  const MatrixXd A = gaussian(3, 7, engine);
  const VectorXd b = gaussian(3, engine);
  const Result<VectorXd> x = constrained_least_squares(MatrixXd::Identity(7, 7), A, b);
  ASSERT_TRUE(x.ok()) << x.error().message;
  const VectorXd reference = A.transpose() * (A * A.transpose()).ldlt().solve(b);
  EXPECT_LE((*x - reference).norm(), 1e-12 * reference.norm());
}

TEST(ConstrainedLeastSquares, DiagonalPositiveWeightsMatchClosedForm) {
  // A.2.2 alone: min Σ λ_i x_i² s.t. Ax = b gives x = Λ⁻¹Aᵀ(AΛ⁻¹Aᵀ)⁻¹b.
  std::mt19937_64 engine(13);
  const VectorXd lambda = (VectorXd(6) << 0.5, 2, 3, 1e-3, 7, 40).finished();
  const MatrixXd A = gaussian(2, 6, engine);
  const VectorXd b = gaussian(2, engine);
  const Result<VectorXd> x = constrained_least_squares(MatrixXd(lambda.asDiagonal()), A, b);
  ASSERT_TRUE(x.ok()) << x.error().message;
  const MatrixXd W = lambda.cwiseInverse().asDiagonal();
  const VectorXd reference = W * A.transpose() * (A * W * A.transpose()).ldlt().solve(b);
  EXPECT_LE((*x - reference).norm(), 1e-11 * reference.norm());
}

TEST(ConstrainedLeastSquares, SingularWeightMatchesNullSpaceBruteForce) {
  std::mt19937_64 engine(21);
  struct Shape {
    int n, rank, m;
  };
  // Null space larger than, equal to and smaller than the number of constraints.
  const std::vector<Shape> shapes = {{8, 3, 2}, {8, 5, 4}, {10, 4, 6}, {6, 5, 1}, {9, 6, 3}, {12, 8, 5}, {5, 1, 5}};
  for (const Shape& shape : shapes) {
    for (int trial = 0; trial < 3; ++trial) {
      SCOPED_TRACE("n = " + std::to_string(shape.n) + ", rank P = " + std::to_string(shape.rank) +
                   ", m = " + std::to_string(shape.m));
      const MatrixXd P = random_psd(shape.n, shape.rank, engine);
      const MatrixXd A = gaussian(shape.m, shape.n, engine);
      const VectorXd b = gaussian(shape.m, engine);
      expect_matches_brute_force(P, A, b);
    }
  }
}

TEST(ConstrainedLeastSquares, RankDeficientZeroWeightBlockIsMinimumNorm) {
  // Constraints partly orthogonal to null(P): A₂ = AU₂ loses rank, R₂ has more columns than
  // non-zero rows (A.2.3's rank-deficient case) and the least-norm tie-break decides x₂.
  std::mt19937_64 engine(22);
  for (int trial = 0; trial < 5; ++trial) {
    const int n = 9;
    const MatrixXd B = gaussian(5, n, engine);
    const MatrixXd P = B.transpose() * B;  // null space of dimension 4
    MatrixXd A(4, n);
    A.topRows(2) = gaussian(2, n, engine);
    A.bottomRows(2) = gaussian(2, 5, engine) * B;  // rows in range(P) = row space of B
    const VectorXd b = gaussian(4, engine);
    expect_matches_brute_force(P, A, b);
  }
  // Every constraint in range(P): A₂ = 0, all of it falls on the positive weights.
  for (int trial = 0; trial < 3; ++trial) {
    const int n = 7;
    const MatrixXd B = gaussian(4, n, engine);
    const MatrixXd P = B.transpose() * B;
    const MatrixXd A = gaussian(3, 4, engine) * B;
    const VectorXd b = gaussian(3, engine);
    expect_matches_brute_force(P, A, b);
  }
}

TEST(ConstrainedLeastSquares, ZeroWeightGivesMinimumNormSolution) {
  std::mt19937_64 engine(23);
  const MatrixXd A = gaussian(3, 6, engine);
  const VectorXd b = gaussian(3, engine);
  const Result<VectorXd> x = constrained_least_squares(MatrixXd::Zero(6, 6), A, b);
  ASSERT_TRUE(x.ok()) << x.error().message;
  const VectorXd reference = A.transpose() * (A * A.transpose()).ldlt().solve(b);
  EXPECT_LE((*x - reference).norm(), 1e-12 * reference.norm());
}

TEST(ConstrainedLeastSquares, ScaledWeightGivesSameSolution) {
  // xᵀ(cP)x has the same minimisers for any c > 0; the tolerances are relative to λ_max.
  std::mt19937_64 engine(24);
  const MatrixXd P = random_psd(8, 5, engine);
  const MatrixXd A = gaussian(4, 8, engine);
  const VectorXd b = gaussian(4, engine);
  const Result<VectorXd> x = constrained_least_squares(P, A, b);
  ASSERT_TRUE(x.ok()) << x.error().message;
  for (const double c : {1e-8, 1e6}) {
    const Result<VectorXd> scaled = constrained_least_squares(c * P, A, b);
    ASSERT_TRUE(scaled.ok()) << scaled.error().message;
    EXPECT_LE((*scaled - *x).norm(), 1e-9 * x->norm()) << "c = " << c;
  }
}

TEST(ConstrainedLeastSquares, OperatorAppliedToBMatchesSolve) {
  std::mt19937_64 engine(31);
  const MatrixXd P = random_psd(10, 6, engine);
  const MatrixXd A = gaussian(5, 10, engine);
  const Result<MatrixXd> K = constrained_least_squares_operator(P, A);
  ASSERT_TRUE(K.ok()) << K.error().message;
  ASSERT_EQ(K->rows(), 10);
  ASSERT_EQ(K->cols(), 5);
  // A K = I: every right-hand side is met.
  EXPECT_LE((A * *K - MatrixXd::Identity(5, 5)).cwiseAbs().maxCoeff(), 1e-10);
  for (int trial = 0; trial < 5; ++trial) {
    const VectorXd b = gaussian(5, engine);
    const Result<VectorXd> x = constrained_least_squares(P, A, b);
    ASSERT_TRUE(x.ok()) << x.error().message;
    EXPECT_LE((*K * b - *x).norm(), 1e-12 * std::max(1.0, x->norm()));
    EXPECT_LE((*K * b - null_space_solution(P, A, b)).norm(), 1e-8 * std::max(1.0, x->norm()));
    EXPECT_LE((A * *x - b).norm(), 1e-10 * b.norm());
  }
}

void expect_invalid(const Result<MatrixXd>& result, const char* what) {
  ASSERT_FALSE(result.ok()) << what;
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument) << what;
  EXPECT_FALSE(result.error().message.empty()) << what;
}

void expect_invalid(const Result<VectorXd>& result, const char* what) {
  ASSERT_FALSE(result.ok()) << what;
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument) << what;
  EXPECT_FALSE(result.error().message.empty()) << what;
}

TEST(ConstrainedLeastSquares, RejectsSizeMismatches) {
  std::mt19937_64 engine(41);
  const MatrixXd P = random_psd(5, 5, engine);
  const MatrixXd A = gaussian(2, 5, engine);
  expect_invalid(constrained_least_squares_operator(MatrixXd::Identity(5, 4), gaussian(2, 4, engine)),
                 "non-square P");
  expect_invalid(constrained_least_squares_operator(P, gaussian(2, 4, engine)), "A with too few columns");
  expect_invalid(constrained_least_squares_operator(P, gaussian(2, 6, engine)), "A with too many columns");
  expect_invalid(constrained_least_squares_operator(P, MatrixXd(0, 5)), "no constraints");
  expect_invalid(constrained_least_squares_operator(P, gaussian(6, 5, engine)), "more constraints than unknowns");
  expect_invalid(constrained_least_squares(P, A, gaussian(3, engine)), "b too long");
  expect_invalid(constrained_least_squares(P, A, gaussian(1, engine)), "b too short");
}

TEST(ConstrainedLeastSquares, RejectsNonFiniteEntries) {
  std::mt19937_64 engine(42);
  const MatrixXd P = random_psd(5, 3, engine);
  const MatrixXd A = gaussian(2, 5, engine);
  const VectorXd b = gaussian(2, engine);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  MatrixXd bad_P = P;
  bad_P(1, 2) = bad_P(2, 1) = nan;
  expect_invalid(constrained_least_squares_operator(bad_P, A), "NaN in P");
  bad_P(1, 2) = bad_P(2, 1) = inf;
  expect_invalid(constrained_least_squares_operator(bad_P, A), "infinity in P");
  MatrixXd bad_A = A;
  bad_A(1, 4) = nan;
  expect_invalid(constrained_least_squares_operator(P, bad_A), "NaN in A");
  VectorXd bad_b = b;
  bad_b(0) = nan;
  expect_invalid(constrained_least_squares(P, A, bad_b), "NaN in b");
  bad_b(0) = -inf;
  expect_invalid(constrained_least_squares(P, A, bad_b), "infinity in b");
}

TEST(ConstrainedLeastSquares, RejectsNonSymmetricOrIndefiniteP) {
  std::mt19937_64 engine(43);
  MatrixXd P = random_psd(5, 5, engine);
  const MatrixXd A = gaussian(2, 5, engine);
  MatrixXd asymmetric = P;
  asymmetric(0, 3) += 1e-3 * P.cwiseAbs().maxCoeff();
  expect_invalid(constrained_least_squares_operator(asymmetric, A), "non-symmetric P");
  // Asymmetry at rounding level is accepted.
  MatrixXd nearly = P;
  nearly(0, 3) += 1e-13 * P.cwiseAbs().maxCoeff();
  EXPECT_TRUE(constrained_least_squares_operator(nearly, A).ok());

  const VectorXd lambda = (VectorXd(5) << 3, 2, 1, 0, -0.5).finished();
  const MatrixXd U = Eigen::HouseholderQR<MatrixXd>(gaussian(5, 5, engine)).householderQ();
  expect_invalid(constrained_least_squares_operator(U * lambda.asDiagonal() * U.transpose(), A), "indefinite P");
  // A negative eigenvalue at rounding level of λ_max is a zero.
  const VectorXd rounding = (VectorXd(5) << 3, 2, 1, 0, -1e-14).finished();
  MatrixXd almost = U * rounding.asDiagonal() * U.transpose();
  almost = 0.5 * (almost + almost.transpose());
  EXPECT_TRUE(constrained_least_squares_operator(almost, A).ok());
}

TEST(ConstrainedLeastSquares, RejectsRankDeficientConstraints) {
  std::mt19937_64 engine(44);
  const MatrixXd P = random_psd(6, 4, engine);
  MatrixXd A = gaussian(3, 6, engine);
  A.row(2) = 2 * A.row(0) - 0.5 * A.row(1);
  expect_invalid(constrained_least_squares_operator(P, A), "dependent rows");
  expect_invalid(constrained_least_squares_operator(P, MatrixXd::Zero(2, 6)), "zero A");
  expect_invalid(constrained_least_squares(P, A, gaussian(3, engine)), "dependent rows, solve");
}

}  // namespace
}  // namespace animspace::lod
