// Tests of thin PCA and the choice of M. Reference values come from matrices built with a known
// SVD (X = B diag(s) Wᵀ with B, W orthonormal), from Eigen's JacobiSVD of X (an independent
// one-sided Jacobi computation, not the Gram route under test), or from hand-built residuals.
#include "core/pmsc/pca.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/common/parallel.h"
#include "tests/support/random_matrices.h"

namespace animspace::pmsc {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

using testing::gaussian_matrix;
using testing::random_orthonormal;

// R × F with singular values exactly `s` (up to the rounding of the product): B diag(s) Wᵀ.
MatrixXd with_singular_values(Index R, Index F, const VectorXd& s, uint64_t seed) {
  const MatrixXd B = random_orthonormal(R, s.size(), seed);
  const MatrixXd W = random_orthonormal(F, s.size(), seed + 1000);
  return B * s.asDiagonal() * W.transpose();
}

double orthonormality_error(const MatrixXd& A) {
  return (A.transpose() * A - MatrixXd::Identity(A.cols(), A.cols())).cwiseAbs().maxCoeff();
}

double relative_projection_error(const MatrixXd& A, const MatrixXd& X) {
  return (X - A * (A.transpose() * X)).norm() / X.norm();
}

// ---------------------------------------------------------------------------------------------
// thin_pca

TEST(PcaThin, RecoversTheRankOfALowRankProductAndItsSingularValues) {
  struct Case {
    Index R, F, r;
    int max_vectors;
  };
  for (const Case c : {Case{3000, 40, 5, 10}, Case{30006, 88, 12, 88}, Case{90, 20, 1, 20},
                       Case{600, 30, 30, 40}}) {
    SCOPED_TRACE(::testing::Message() << c.R << "×" << c.F << " rank " << c.r);
    const MatrixXd B = random_orthonormal(c.R, c.r, 7);
    const MatrixXd X = B * gaussian_matrix(c.r, c.F, 8);
    const PcaBasis pca = thin_pca(X, c.max_vectors);

    ASSERT_EQ(pca.basis.cols(), c.r);
    ASSERT_EQ(pca.basis.rows(), c.R);
    ASSERT_EQ(pca.singular_values.size(), c.r);
    EXPECT_LT(orthonormality_error(pca.basis), 1e-12);
    EXPECT_LT(relative_projection_error(pca.basis, X), 1e-10);
    // The basis spans B's columns.
    EXPECT_LT((B - pca.basis * (pca.basis.transpose() * B)).norm(), 1e-10);

    const Eigen::JacobiSVD<MatrixXd> reference(X);
    for (Index i = 0; i < c.r; ++i) {
      EXPECT_NEAR(pca.singular_values(i), reference.singularValues()(i),
                  1e-9 * reference.singularValues()(i))
          << "σ_" << i;
    }
  }
}

TEST(PcaThin, LeadingVectorsAreTheLeftSingularVectorsWhenFewerAreAsked) {
  const VectorXd s = (VectorXd(6) << 9.0, 7.0, 5.0, 3.0, 2.0, 1.0).finished();
  const MatrixXd X = with_singular_values(500, 25, s, 11);
  const PcaBasis pca = thin_pca(X, 3);
  ASSERT_EQ(pca.basis.cols(), 3);
  const Eigen::JacobiSVD<MatrixXd> reference(X, Eigen::ComputeThinU);
  for (Index i = 0; i < 3; ++i) {
    EXPECT_NEAR(pca.singular_values(i), s(i), 1e-12 * s(0));
    // Equal up to sign: |⟨a_i, u_i⟩| = 1.
    EXPECT_NEAR(std::abs(pca.basis.col(i).dot(reference.matrixU().col(i))), 1.0, 1e-12);
  }
}

TEST(PcaThin, StaysOrthonormalForClusteredSingularValues) {
  // Nearly equal σ make the individual eigenvectors ill-determined; only the spanned space is,
  // and the columns must still be orthonormal.
  VectorXd s(8);
  s << 1.0, 1.0 + 1e-13, 1.0 + 2e-13, 1.0 - 1e-13, 0.5, 0.5 * (1.0 + 1e-14), 1e-3, 1e-3;
  const MatrixXd X = with_singular_values(4000, 30, s, 21);
  const PcaBasis pca = thin_pca(X, 30);
  ASSERT_EQ(pca.basis.cols(), 8);
  EXPECT_LT(orthonormality_error(pca.basis), 1e-12);
  EXPECT_LT(relative_projection_error(pca.basis, X), 1e-10);
  for (Index i = 1; i < 8; ++i) EXPECT_GE(pca.singular_values(i - 1), pca.singular_values(i));
}

TEST(PcaThin, DropsDirectionsBelowTheRelativeFloorAndKeepsThoseAbove) {
  // σ = 1e-9·σ_0 is under the 1e-7 floor; 1e-5·σ_0 is well above it and must be resolved.
  const VectorXd s = (VectorXd(4) << 2.0, 1.0, 2e-5, 2e-9).finished();
  const MatrixXd X = with_singular_values(2000, 16, s, 31);
  const PcaBasis pca = thin_pca(X, 16);
  ASSERT_EQ(pca.basis.cols(), 3);
  EXPECT_NEAR(pca.singular_values(0), 2.0, 1e-12);
  EXPECT_NEAR(pca.singular_values(1), 1.0, 1e-12);
  EXPECT_NEAR(pca.singular_values(2), 2e-5, 1e-9 * 2e-5);
  EXPECT_LT(orthonormality_error(pca.basis), 1e-12);
}

TEST(PcaThin, ScalesWithTheDataAndKeepsTheSameBasis) {
  const MatrixXd X = gaussian_matrix(1200, 12, 41);
  const PcaBasis unit = thin_pca(X, 12);
  for (const double scale : {1e-4, 1e4}) {
    SCOPED_TRACE(scale);
    const PcaBasis scaled = thin_pca(scale * X, 12);
    ASSERT_EQ(scaled.basis.cols(), unit.basis.cols());
    EXPECT_LT((scaled.singular_values - scale * unit.singular_values).norm(),
              1e-12 * scale * unit.singular_values(0));
    EXPECT_LT((scaled.basis - unit.basis).cwiseAbs().maxCoeff(), 1e-10);
  }
}

TEST(PcaThin, SignConventionMakesTheLargestEntryPositiveAndIgnoresTheSignOfX) {
  const MatrixXd X = gaussian_matrix(800, 10, 51);
  const PcaBasis pca = thin_pca(X, 10);
  for (Index j = 0; j < pca.basis.cols(); ++j) {
    Index largest = 0;
    pca.basis.col(j).cwiseAbs().maxCoeff(&largest);
    EXPECT_GT(pca.basis(largest, j), 0.0) << "column " << j;
  }
  const PcaBasis negated = thin_pca(-X, 10);
  EXPECT_LT((negated.basis - pca.basis).cwiseAbs().maxCoeff(), 1e-12);
  const PcaBasis again = thin_pca(X, 10);
  EXPECT_EQ(again.basis, pca.basis);
}

TEST(PcaThin, WideMatricesUseTheOtherSide) {
  const MatrixXd X = gaussian_matrix(6, 20, 61);
  const PcaBasis pca = thin_pca(X, 10);
  ASSERT_EQ(pca.basis.cols(), 6);
  EXPECT_LT(orthonormality_error(pca.basis), 1e-12);
  EXPECT_LT(relative_projection_error(pca.basis, X), 1e-12);
  const Eigen::JacobiSVD<MatrixXd> reference(X);
  for (Index i = 0; i < 6; ++i) {
    EXPECT_NEAR(pca.singular_values(i), reference.singularValues()(i),
                1e-9 * reference.singularValues()(i));
  }
  // Wide and rank deficient: 9 × 30 of rank 4.
  const MatrixXd Y = random_orthonormal(9, 4, 62) * gaussian_matrix(4, 30, 63);
  const PcaBasis low = thin_pca(Y, 30);
  EXPECT_EQ(low.basis.cols(), 4);
  EXPECT_LT(relative_projection_error(low.basis, Y), 1e-12);
}

TEST(PcaThin, ZeroEmptyAndNoVectorsGiveAnEmptyBasis) {
  EXPECT_EQ(thin_pca(MatrixXd::Zero(30, 5), 5).basis.cols(), 0);
  EXPECT_EQ(thin_pca(MatrixXd::Zero(30, 5), 5).basis.rows(), 30);
  EXPECT_EQ(thin_pca(MatrixXd(30, 0), 5).basis.cols(), 0);
  EXPECT_EQ(thin_pca(gaussian_matrix(30, 5, 71), 0).basis.cols(), 0);
  EXPECT_EQ(thin_pca(gaussian_matrix(30, 5, 71), 0).singular_values.size(), 0);
}

// ---------------------------------------------------------------------------------------------
// max_point_error

TEST(PcaMaxPointError, IsTheLargestPointNormPerFrame) {
  // Two points of 3 channels, three frames. Frame 0: point 1 = (3, 4, 0) → 5. Frame 1: point 0 =
  // (1, 2, 2) → 3 beats point 1 = (0, 0, -2) → 2. Frame 2: all zero.
  MatrixXd residual(6, 3);
  residual << 1, 1, 0,   //
      0, 2, 0,           //
      0, 2, 0,           //
      3, 0, 0,           //
      4, 0, 0,           //
      0, -2, 0;
  const VectorXd per_frame = max_point_error_per_frame(residual, 3);
  ASSERT_EQ(per_frame.size(), 3);
  EXPECT_DOUBLE_EQ(per_frame(0), 5.0);
  EXPECT_DOUBLE_EQ(per_frame(1), 3.0);
  EXPECT_DOUBLE_EQ(per_frame(2), 0.0);
  EXPECT_DOUBLE_EQ(max_point_error(residual, 3), 5.0);
  // One channel: the largest absolute entry. Two channels: points (1,0),(0,3),(4,0) in frame 0
  // and (1,2),(2,0),(0,-2) in frame 1.
  EXPECT_DOUBLE_EQ(max_point_error(residual, 1), 4.0);
  EXPECT_DOUBLE_EQ(max_point_error_per_frame(residual, 2)(0), 4.0);
  EXPECT_DOUBLE_EQ(max_point_error_per_frame(residual, 2)(1), std::sqrt(5.0));
  EXPECT_DOUBLE_EQ(max_point_error(MatrixXd(6, 0), 3), 0.0);
}

// ---------------------------------------------------------------------------------------------
// thin_pca in halves, from a Gram matrix formed another way

TEST(PcaFromGram, TheLeadingEigenvectorsAreTheRightSingularVectorsInOrder) {
  // X = B diag(s) Wᵀ: XᵀX = W diag(s²) Wᵀ, so its eigenvectors are W's columns, largest first.
  const VectorXd s = (VectorXd(4) << 9, 5, 2, 0.5).finished();
  const Index R = 90, F = 12;
  const MatrixXd B = random_orthonormal(R, 4, 301);
  const MatrixXd W = random_orthonormal(F, 4, 302);
  const MatrixXd X = B * s.asDiagonal() * W.transpose();
  MatrixXd gram = X.transpose() * X;
  gram.triangularView<Eigen::StrictlyUpper>().setConstant(1e300);  // only the lower triangle is read
  const MatrixXd V = leading_gram_eigenvectors(gram, 3);
  ASSERT_EQ(V.rows(), F);
  ASSERT_EQ(V.cols(), 3);
  for (Index i = 0; i < 3; ++i) EXPECT_NEAR(std::abs(V.col(i).dot(W.col(i))), 1.0, 1e-12) << "vector " << i;
  EXPECT_EQ(leading_gram_eigenvectors(gram, 40).cols(), F);  // never more than F

  // From X·V: σ_i = ‖X v_i‖ = s_i, and the basis is thin_pca's (same columns, same signs).
  const PcaBasis halves = pca_from_directions(X * V);
  const PcaBasis whole = thin_pca(X, 3);
  ASSERT_EQ(halves.basis.cols(), 3);
  for (Index i = 0; i < 3; ++i) EXPECT_NEAR(halves.singular_values(i), s(i), 1e-12 * s(0));
  EXPECT_LT((halves.basis - whole.basis).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT(orthonormality_error(halves.basis), 1e-14);
}

// ---------------------------------------------------------------------------------------------
// residual_pass

TEST(PcaResidualPass, EqualsTheFormedResidualOnAnyThreadCount) {
  // Points on both sides of a block (kResidualBlockPoints) and a last block cut short; the
  // residual formed whole (Eigen, one expression) is the reference.
  const Index D = 3, N = 2 * kResidualBlockPoints + 77, R = N * D, F = 23, M = 5, k = 4;
  const MatrixXd X = gaussian_matrix(R, F, 311);
  const MatrixXd A = gaussian_matrix(R, M, 312);
  const MatrixXd C = gaussian_matrix(M, F, 313);
  const MatrixXd directions = gaussian_matrix(F, k, 314);
  const MatrixXd E = X - A * C;
  const double expected = max_point_error(E, static_cast<int>(D));
  const MatrixXd expected_projected = E * directions;

  MatrixXd one, two;
  set_thread_limit(1);
  const double on_one = residual_pass(X, A, C, static_cast<int>(D), directions, &one);
  set_thread_limit(2);
  const double on_two = residual_pass(X, A, C, static_cast<int>(D), directions, &two);
  set_thread_limit(0);
  // Each entry of E is a sum of M + 1 terms of size ~1: within a few ε of the reference.
  EXPECT_NEAR(on_one, expected, 1e-13 * expected);
  ASSERT_EQ(one.rows(), R);
  ASSERT_EQ(one.cols(), k);
  EXPECT_LT((one - expected_projected).cwiseAbs().maxCoeff(), 1e-12 * expected_projected.cwiseAbs().maxCoeff());
  // The blocks do not depend on the threads: the same bits.
  EXPECT_EQ(on_one, on_two);
  EXPECT_TRUE(one == two);
  // Without directions: the error alone.
  EXPECT_EQ(residual_pass(X, A, C, static_cast<int>(D)), on_one);
  // A hand-built case: the only nonzero residual is point N − 1's (3, 4, 0) in frame 2.
  MatrixXd Y = A * C;
  Y(R - 3, 2) += 3;
  Y(R - 2, 2) += 4;
  EXPECT_NEAR(residual_pass(Y, A, C, static_cast<int>(D)), 5.0, 1e-12);
}

// ---------------------------------------------------------------------------------------------
// choose_basis_size

TEST(PcaChooseBasisSize, FindsTheRankOfLowRankDataUnderNoise) {
  // Rank 3 with σ ≈ 6 plus noise of 1e-6 per entry: the noise directions (σ ≈ 1e-4, above the
  // 1e-7 floor) are in the basis, and the worst point error of the noise is ~1e-5.
  const Index N = 2000, D = 3, F = 40;
  const MatrixXd clean = random_orthonormal(N * D, 3, 81) * gaussian_matrix(3, F, 82);
  const MatrixXd X = clean + 1e-6 * gaussian_matrix(N * D, F, 83);
  const PcaBasis pca = thin_pca(X, 20);
  ASSERT_EQ(pca.basis.cols(), 20);
  EXPECT_EQ(choose_basis_size(X, pca, 3, 1e-4, 20), 3);
  // Below the noise no M qualifies: the largest allowed.
  EXPECT_EQ(choose_basis_size(X, pca, 3, 1e-9, 20), 20);
  EXPECT_EQ(choose_basis_size(X, pca, 3, 1e-9, 5), 5);
}

TEST(PcaChooseBasisSize, NoiseBelowTheFloorLeavesOnlyTheSignal) {
  // Noise 1e-6 below σ_0 · 1e-7 has no basis vectors, so M can be at most the rank.
  const Index N = 2000, D = 3, F = 40;
  const MatrixXd clean = random_orthonormal(N * D, 3, 84) * (1e4 * gaussian_matrix(3, F, 85));
  const MatrixXd X = clean + 1e-6 * gaussian_matrix(N * D, F, 86);
  const PcaBasis pca = thin_pca(X, 20);
  EXPECT_EQ(pca.basis.cols(), 3);
  EXPECT_EQ(choose_basis_size(X, pca, 3, 1e-9, 20), 3);
}

TEST(PcaChooseBasisSize, MatchesHandBuiltPerPointErrors) {
  // Basis vector m lives on point m only, as (0.6, 0.8, 0), with amplitude s_m and time course
  // w_m = row m of a 4 × 4 Hadamard matrix / 2 (orthonormal, entries ±1/2). So X has the SVD
  // Σ s_m b_m w_mᵀ, and after removing the first M terms the worst point error is s_M / 2.
  const Index N = 6, D = 3, F = 4;
  const std::vector<double> s = {10.0, 6.0, 4.0, 2.0};
  MatrixXd hadamard(4, 4);
  hadamard << 1, 1, 1, 1,  //
      1, -1, 1, -1,        //
      1, 1, -1, -1,        //
      1, -1, -1, 1;
  MatrixXd X = MatrixXd::Zero(N * D, F);
  for (Index m = 0; m < 4; ++m) {
    X.row(m * D + 0) = s[static_cast<size_t>(m)] * 0.6 * 0.5 * hadamard.row(m);
    X.row(m * D + 1) = s[static_cast<size_t>(m)] * 0.8 * 0.5 * hadamard.row(m);
  }
  const PcaBasis pca = thin_pca(X, 10);
  ASSERT_EQ(pca.basis.cols(), 4);
  // Errors after M = 1, 2, 3, 4: 3, 2, 1, 0.
  struct Case {
    double bound;
    int expected;
  };
  // Bounds sit 1e-9 either side of the exact errors, well outside rounding.
  for (const Case c : {Case{3.5, 1}, Case{3.0 + 1e-9, 1}, Case{3.0 - 1e-9, 2}, Case{2.0 + 1e-9, 2},
                       Case{1.5, 3}, Case{1.0 + 1e-9, 3}, Case{1.0 - 1e-9, 4}, Case{0.0, 4}}) {
    EXPECT_EQ(choose_basis_size(X, pca, 3, c.bound, 10), c.expected) << "bound " << c.bound;
  }
  EXPECT_EQ(choose_basis_size(X, pca, 3, 0.5, 2), 2);
}

TEST(PcaChooseBasisSize, AgreesWithRecomputingTheResidualFromScratch) {
  const Index R = 3 * 400, F = 30;
  const MatrixXd X = gaussian_matrix(R, 8, 91) * gaussian_matrix(8, F, 92) +
                     0.01 * gaussian_matrix(R, F, 93);
  const PcaBasis pca = thin_pca(X, 20);
  // Per-M errors by the direct formula X − A_M A_Mᵀ X, point norms written out by hand.
  std::vector<double> error_at;
  for (Index M = 1; M <= pca.basis.cols(); ++M) {
    const MatrixXd A = pca.basis.leftCols(M);
    const MatrixXd E = X - A * (A.transpose() * X);
    double worst = 0.0;
    for (Index f = 0; f < F; ++f) {
      for (Index p = 0; p < R / 3; ++p) {
        worst = std::max(worst, std::hypot(E(3 * p, f), E(3 * p + 1, f), E(3 * p + 2, f)));
      }
    }
    error_at.push_back(worst);
  }
  for (const double bound : {100.0, 10.0, 3.0, 1.0, 0.3, 0.1, 0.05}) {
    int expected = static_cast<int>(error_at.size());
    for (size_t m = 0; m < error_at.size(); ++m) {
      if (error_at[m] <= bound) {
        expected = static_cast<int>(m) + 1;
        break;
      }
    }
    EXPECT_EQ(choose_basis_size(X, pca, 3, bound, 20), expected) << "bound " << bound;
  }
}

TEST(PcaChooseBasisSize, EmptyBasisGivesZero) {
  const MatrixXd X = MatrixXd::Zero(9, 4);
  EXPECT_EQ(choose_basis_size(X, thin_pca(X, 4), 3, 0.1, 4), 0);
}

// ---------------------------------------------------------------------------------------------
// TrainingMatrix (issue #53): the frames read in place, a block of rows promoted at a time

// Float frames F × R row-major (as a point cache is read), over more rows than one block, against
// their explicit double copy less the mean: every value, every product and what the PCA, the
// choice of M and the residual pass make of them.
TEST(TrainingMatrixTest, FloatFramesReadInPlaceAreTheirCentredDoubleCopy) {
  const Index points = 1100, D = 3, R = points * D, F = 24;
  ASSERT_GT(R, TrainingMatrix::kBlockRows);
  const MatrixXd low_rank = random_orthonormal(R, 5, 91) * (10.0 * gaussian_matrix(5, F, 92)) +
                            0.01 * gaussian_matrix(R, F, 93) + MatrixXd::Constant(R, F, 3.0);
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> frames =
      low_rank.transpose().cast<float>();
  const MatrixXd T = frames.transpose().cast<double>();
  const VectorXd mean = T.rowwise().mean();
  const MatrixXd X = T.colwise() - mean;

  const TrainingMatrix values(frames.data(), R, F);
  EXPECT_LT((values.value_mean() - mean).cwiseAbs().maxCoeff(), 1e-12);
  const TrainingMatrix centred = values.with_offset(mean);
  ASSERT_EQ(centred.rows(), R);
  ASSERT_EQ(centred.cols(), F);
  EXPECT_EQ(centred.col(7), X.col(7));
  MatrixXd block(10, F);
  centred.rows_into(R - 10, 10, block);
  EXPECT_EQ(block, X.bottomRows(10));
  const std::vector<int> points_asked = {0, 1099, 512};
  for (size_t k = 0; k < points_asked.size(); ++k) {
    EXPECT_EQ(centred.gather_rows(points_asked, 3).middleRows(static_cast<Index>(k) * 3, 3),
              X.middleRows(points_asked[k] * 3, 3));
  }
  const double scale = X.squaredNorm();
  EXPECT_LT((centred.gram() - X.transpose() * X).cwiseAbs().maxCoeff(), 1e-13 * scale);
  const MatrixXd W = gaussian_matrix(F, 4, 94);
  MatrixXd product;
  centred.times(W, product);
  EXPECT_LT((product - X * W).cwiseAbs().maxCoeff(), 1e-12 * (X * W).cwiseAbs().maxCoeff());
  const MatrixXd A = random_orthonormal(R, 4, 95);
  EXPECT_LT((centred.transposed_times(A) - A.transpose() * X).cwiseAbs().maxCoeff(), 1e-12 * std::sqrt(scale));

  const PcaBasis from_view = thin_pca(centred, 8);
  const PcaBasis from_copy = thin_pca(X, 8);
  ASSERT_EQ(from_view.basis.cols(), from_copy.basis.cols());
  EXPECT_LT((from_view.singular_values - from_copy.singular_values).cwiseAbs().maxCoeff(),
            1e-10 * from_copy.singular_values(0));
  // The five signal directions are well separated: the same vectors, signs fixed alike.
  EXPECT_LT((from_view.basis.leftCols(5) - from_copy.basis.leftCols(5)).cwiseAbs().maxCoeff(), 1e-9);

  // The choice of M against its definition: the worst point of X − A_M A_Mᵀ X, for each M.
  const MatrixXd& basis = from_copy.basis;
  std::vector<double> worst;
  for (Index m = 1; m <= basis.cols(); ++m) {
    const MatrixXd residual = X - basis.leftCols(m) * (basis.leftCols(m).transpose() * X);
    worst.push_back(max_point_error(residual, 3));
  }
  for (const double bound : {worst[2] * 1.01, worst[4] * 1.01, worst[6] * 1.01, worst.back() * 0.5}) {
    const int by_definition =
        static_cast<int>(std::find_if(worst.begin(), worst.end(), [&](double w) { return w <= bound; }) - worst.begin()) + 1;
    EXPECT_EQ(choose_basis_size(centred, from_copy, 3, bound, 8), std::min<int>(by_definition, 8)) << bound;
  }

  // The residual pass reads the same residual.
  const MatrixXd C = basis.leftCols(3).transpose() * X;
  const MatrixXd directions = gaussian_matrix(F, 2, 96);
  MatrixXd from_view_projected, from_copy_projected;
  EXPECT_NEAR(residual_pass(centred, basis.leftCols(3), C, 3, directions, &from_view_projected),
              residual_pass(X, basis.leftCols(3), C, 3, directions, &from_copy_projected), 1e-12);
  EXPECT_LT((from_view_projected - from_copy_projected).cwiseAbs().maxCoeff(), 1e-10);
}

}  // namespace
}  // namespace animspace::pmsc
