// Tests of the varimax rotation. Optimality is checked independently of the iteration: by the
// first-order condition for a maximum over orthogonal matrices (QᵀG symmetric, G the gradient
// written out here), by small rotations never increasing the criterion, and by recovering a
// planted simple structure.
#include "core/pmsc/varimax.h"

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "tests/support/random_matrices.h"

namespace animspace::pmsc {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;

using testing::gaussian_matrix;
using testing::random_orthonormal;

// Loadings that look like a PCA block of localised motions: each column a smooth bump on its
// own range of rows plus a little global motion, mixed by a random rotation.
MatrixXd pca_like_loadings(Index R, Index k, uint64_t seed) {
  MatrixXd S = 0.05 * gaussian_matrix(R, k, seed);
  for (Index j = 0; j < k; ++j) {
    const double centre = (static_cast<double>(j) + 0.5) * static_cast<double>(R) /
                          static_cast<double>(k);
    for (Index i = 0; i < R; ++i) {
      const double t = (static_cast<double>(i) - centre) / (0.3 * static_cast<double>(R) /
                                                            static_cast<double>(k));
      S(i, j) += std::exp(-t * t);
    }
  }
  return S * random_orthonormal(k, k, seed + 1);
}

// Plain four-moment definition, written independently of varimax_criterion's two-pass form.
double criterion_by_moments(const MatrixXd& L) {
  const double R = static_cast<double>(L.rows());
  double v = 0.0;
  for (Index j = 0; j < L.cols(); ++j) {
    double m2 = 0.0, m4 = 0.0;
    for (Index i = 0; i < L.rows(); ++i) {
      m2 += std::pow(L(i, j), 2) / R;
      m4 += std::pow(L(i, j), 4) / R;
    }
    v += m4 - m2 * m2;
  }
  return v;
}

// dV/dQ at Q for V(LQ): Lᵀ (4/R)(Z³ − Z diag(mean squares)), Z = LQ.
MatrixXd criterion_gradient(const MatrixXd& L, const MatrixXd& Q) {
  const MatrixXd Z = L * Q;
  const double R = static_cast<double>(L.rows());
  MatrixXd dZ(Z.rows(), Z.cols());
  for (Index j = 0; j < Z.cols(); ++j) {
    const double mean_square = Z.col(j).squaredNorm() / R;
    for (Index i = 0; i < Z.rows(); ++i) {
      dZ(i, j) = 4.0 / R * (std::pow(Z(i, j), 3) - mean_square * Z(i, j));
    }
  }
  return L.transpose() * dZ;
}

double orthogonality_error(const MatrixXd& Q) {
  return (Q.transpose() * Q - MatrixXd::Identity(Q.cols(), Q.cols())).cwiseAbs().maxCoeff();
}

// True when every column of `found` equals ± a distinct column of `expected` to `tolerance`.
::testing::AssertionResult equal_up_to_permutation_and_sign(const MatrixXd& found,
                                                            const MatrixXd& expected,
                                                            double tolerance) {
  std::vector<bool> used(static_cast<size_t>(expected.cols()), false);
  for (Index j = 0; j < found.cols(); ++j) {
    bool matched = false;
    for (Index c = 0; c < expected.cols() && !matched; ++c) {
      if (used[static_cast<size_t>(c)]) continue;
      for (const double sign : {1.0, -1.0}) {
        if ((found.col(j) - sign * expected.col(c)).cwiseAbs().maxCoeff() <= tolerance) {
          used[static_cast<size_t>(c)] = matched = true;
          break;
        }
      }
    }
    if (!matched) {
      return ::testing::AssertionFailure() << "column " << j << " matches no expected column";
    }
  }
  return ::testing::AssertionSuccess();
}

// k × k rotation by `angle` in the plane of axes a and b.
MatrixXd plane_rotation(Index k, Index a, Index b, double angle) {
  MatrixXd Q = MatrixXd::Identity(k, k);
  Q(a, a) = std::cos(angle);
  Q(a, b) = -std::sin(angle);
  Q(b, a) = std::sin(angle);
  Q(b, b) = std::cos(angle);
  return Q;
}

// R × k simple structure: row i loads only on column i mod k, with a magnitude that varies.
MatrixXd simple_structure(Index R, Index k) {
  MatrixXd S = MatrixXd::Zero(R, k);
  for (Index i = 0; i < R; ++i) S(i, i % k) = 0.4 + 0.6 * static_cast<double>((i * 7) % 11) / 10.0;
  return S;
}

// ---------------------------------------------------------------------------------------------

TEST(VarimaxCriterion, MatchesHandComputedValues) {
  // (1, 0, 0, 0): E[x⁴] − E[x²]² = 1/4 − 1/16 = 3/16; a constant-magnitude column gives 0.
  MatrixXd L(4, 2);
  L << 1, 2,  //
      0, -2,  //
      0, 2,   //
      0, -2;
  EXPECT_DOUBLE_EQ(varimax_criterion(L), 3.0 / 16.0);
  const MatrixXd random = gaussian_matrix(300, 5, 1);
  EXPECT_NEAR(varimax_criterion(random), criterion_by_moments(random),
              1e-12 * criterion_by_moments(random));
}

TEST(Varimax, RotationIsProperAndOrthogonalAndTheCriterionRises) {
  for (const uint64_t seed : {11u, 12u, 13u, 14u, 15u}) {
    SCOPED_TRACE(seed);
    const Index R = 600, k = static_cast<Index>(3 + seed % 5);
    const MatrixXd L = seed % 2 == 0 ? gaussian_matrix(R, k, seed) : pca_like_loadings(R, k, seed);
    const VarimaxResult result = varimax(L);

    ASSERT_EQ(result.rotation.rows(), k);
    ASSERT_EQ(result.rotation.cols(), k);
    EXPECT_LT(orthogonality_error(result.rotation), 1e-10);
    EXPECT_NEAR(result.rotation.determinant(), 1.0, 1e-10);
    EXPECT_LT((result.rotated - L * result.rotation).cwiseAbs().maxCoeff(),
              1e-14 * L.cwiseAbs().maxCoeff());
    EXPECT_TRUE(result.converged);
    EXPECT_GT(result.iterations, 0);
    EXPECT_NEAR(result.criterion_before, criterion_by_moments(L), 1e-12);
    EXPECT_NEAR(result.criterion_after, criterion_by_moments(result.rotated), 1e-12);
    EXPECT_GE(result.criterion_after, result.criterion_before);

    // The subspace and each row's length (the point's "communality") are unchanged.
    EXPECT_LT((L.rowwise().norm() - result.rotated.rowwise().norm()).cwiseAbs().maxCoeff(), 1e-12);
    const MatrixXd in_span = L * L.colPivHouseholderQr().solve(result.rotated);
    EXPECT_LT((in_span - result.rotated).norm(), 1e-10 * result.rotated.norm());
  }
}

TEST(Varimax, ResultIsAStationaryLocalMaximum) {
  const MatrixXd L = pca_like_loadings(900, 6, 21);
  const VarimaxResult result = varimax(L, 2000, 1e-14);
  ASSERT_TRUE(result.converged);
  // First order: at a maximum of V(LQ) over orthogonal Q, QᵀG is symmetric.
  const MatrixXd QtG = result.rotation.transpose() * criterion_gradient(L, result.rotation);
  EXPECT_LT((QtG - QtG.transpose()).norm(), 1e-6 * QtG.norm());
  // Second order, sampled: small rotations in random planes never raise the criterion.
  const double best = varimax_criterion(result.rotated);
  for (uint64_t seed = 0; seed < 20; ++seed) {
    const MatrixXd A = 1e-3 * gaussian_matrix(6, 6, 100 + seed);
    const MatrixXd half_skew = 0.5 * (A - A.transpose());
    const MatrixXd I = MatrixXd::Identity(6, 6);
    // Cayley transform of a skew matrix: an exact rotation close to I.
    const MatrixXd step = (I - half_skew).inverse() * (I + half_skew);
    EXPECT_LE(varimax_criterion(result.rotated * step), best + 1e-15) << "seed " << seed;
  }
}

TEST(Varimax, RecoversAPlantedSimpleStructure) {
  struct Case {
    Index R, k;
    MatrixXd Q0;
    const char* name;
  };
  const std::vector<Case> cases = {
      {60, 3, plane_rotation(3, 0, 1, std::numbers::pi / 6.0), "30° in the (0,1) plane"},
      {60, 2, plane_rotation(2, 0, 1, -std::numbers::pi / 6.0), "-30°, two columns"},
      {120, 5, random_orthonormal(5, 5, 31), "a random orthogonal 5 × 5"},
  };
  for (const Case& c : cases) {
    for (const VarimaxNormalization normalization :
         {VarimaxNormalization::kNone, VarimaxNormalization::kKaiser}) {
      SCOPED_TRACE(::testing::Message() << c.name << (normalization == VarimaxNormalization::kKaiser
                                                          ? ", Kaiser"
                                                          : ", raw"));
      const MatrixXd S = simple_structure(c.R, c.k);
      const MatrixXd L = S * c.Q0.transpose();
      const VarimaxResult result = varimax(L, 1000, 1e-14, normalization);
      EXPECT_TRUE(result.converged);
      EXPECT_TRUE(equal_up_to_permutation_and_sign(result.rotated, S, 1e-6));
      EXPECT_LT((result.rotated - L * result.rotation).cwiseAbs().maxCoeff(), 1e-14);
    }
  }
}

TEST(Varimax, KaiserNormalisationMaximisesTheRowNormalisedCriterion) {
  MatrixXd L = pca_like_loadings(500, 4, 41);
  // Rows of very different lengths, so that normalisation matters.
  for (Index i = 0; i < L.rows(); ++i) L.row(i) *= 1.0 + 9.0 * static_cast<double>(i % 3 == 0);
  const VarimaxResult result = varimax(L, 200, 1e-9, VarimaxNormalization::kKaiser);
  MatrixXd normalized = L, normalized_rotated = result.rotated;
  for (Index i = 0; i < L.rows(); ++i) {
    normalized.row(i).normalize();
    normalized_rotated.row(i).normalize();
  }
  EXPECT_LT(orthogonality_error(result.rotation), 1e-10);
  EXPECT_NEAR(result.rotation.determinant(), 1.0, 1e-10);
  EXPECT_NEAR(result.criterion_before, criterion_by_moments(normalized), 1e-12);
  EXPECT_NEAR(result.criterion_after, criterion_by_moments(normalized_rotated), 1e-12);
  EXPECT_GT(result.criterion_after, result.criterion_before);
  EXPECT_LT((result.rotated - L * result.rotation).cwiseAbs().maxCoeff(), 1e-13);
}

TEST(Varimax, RotationDoesNotDependOnTheScaleOfTheLoadings) {
  const MatrixXd L = pca_like_loadings(400, 5, 51);
  const VarimaxResult unit = varimax(L);
  for (const double scale : {1e-4, 1e4}) {
    SCOPED_TRACE(scale);
    const VarimaxResult scaled = varimax(scale * L);
    EXPECT_LT((scaled.rotation - unit.rotation).cwiseAbs().maxCoeff(), 1e-8);
    EXPECT_NEAR(scaled.criterion_after, std::pow(scale, 4) * unit.criterion_after,
                1e-10 * std::pow(scale, 4) * unit.criterion_after);
  }
}

TEST(Varimax, OneColumnOrZeroLoadingsGiveTheIdentity) {
  const MatrixXd one = gaussian_matrix(50, 1, 61);
  const VarimaxResult single = varimax(one);
  EXPECT_EQ(single.rotation, MatrixXd::Identity(1, 1));
  EXPECT_EQ(single.rotated, one);
  EXPECT_EQ(single.iterations, 0);
  EXPECT_TRUE(single.converged);
  EXPECT_EQ(single.criterion_after, single.criterion_before);

  const VarimaxResult zero = varimax(MatrixXd::Zero(50, 4));
  EXPECT_EQ(zero.rotation, MatrixXd::Identity(4, 4));
  EXPECT_EQ(zero.iterations, 0);
  EXPECT_TRUE(zero.rotated.isZero(0.0));
}

TEST(Varimax, StopsAtTheIterationLimitWithoutClaimingConvergence) {
  const MatrixXd L = gaussian_matrix(300, 6, 71);
  const VarimaxResult result = varimax(L, 1, 1e-15);
  EXPECT_EQ(result.iterations, 1);
  EXPECT_FALSE(result.converged);
  EXPECT_LT(orthogonality_error(result.rotation), 1e-10);
  EXPECT_GE(result.criterion_after, result.criterion_before);
}

}  // namespace
}  // namespace animspace::pmsc
