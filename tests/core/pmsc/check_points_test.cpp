// Check point selection (issue #35, core/pmsc/check_points.h) on hand-worked cases.
#include "core/pmsc/check_points.h"

#include <cmath>
#include <random>

#include "core/pmsc/relative_point_errors.h"

#include <gtest/gtest.h>

namespace animspace::pmsc {
namespace {

// Three samples over six points, each sample's max error 1; point 0 is a key point with the
// largest error everywhere (it must never be chosen). Normalised errors:
//   s0: 1  0.9  0.2  0    0.95 0.1
//   s1: 1  0.1  1.0  0    0.2  0.9
//   s2: 1  0.1  0.2  1.0  0.1  0
Eigen::MatrixXf hand_errors() {
  Eigen::MatrixXf e(3, 6);
  e << 1, 0.9f, 0.2f, 0, 0.95f, 0.1f,  //
      1, 0.1f, 1.0f, 0, 0.2f, 0.9f,    //
      1, 0.1f, 0.2f, 1.0f, 0.1f, 0;
  return e;
}

TEST(CheckPoints, GreedyCoverageByHand) {
  const Eigen::VectorXd max = Eigen::VectorXd::Ones(3);
  // First the largest column sum among non-keys: p1 1.1, p2 1.4, p3 1.0, p4 1.25, p5 1.0 → p2;
  // coverage (0.2, 1, 0.2). Gains then: p1 0.7, p3 0.8, p4 0.75, p5 0 → p3; coverage (0.2, 1, 1).
  // Then p1 0.7, p4 0.75 → p4.
  EXPECT_EQ(select_check_points(hand_errors(), max, {0}, {}, 0, 3, 1e-6), (std::vector<int>{2, 3, 4}));
  // Never more than the points that are not keys.
  EXPECT_EQ(select_check_points(hand_errors(), max, {0}, {}, 0, 10, 1e-6).size(), 5u);
  EXPECT_TRUE(select_check_points(hand_errors(), max, {0}, {}, 0, 0, 1e-6).empty());
}

TEST(CheckPoints, OnePerRegionFirstInOrderOfTheRegionsError) {
  const Eigen::VectorXd max = Eigen::VectorXd::Ones(3);
  // Regions: {0, 1, 4} and {2, 3, 5}. Region 1's non-key sum 3.4 beats region 0's 2.35, so its
  // best point (p2, 1.4) comes first, then region 0's (p4, 1.25 > p1's 1.1).
  const std::vector<int> regions = {0, 0, 1, 1, 0, 1};
  EXPECT_EQ(select_check_points(hand_errors(), max, {0}, regions, 2, 2, 1e-6), (std::vector<int>{2, 4}));
  // One per region while the count allows: with a count of 1 only region 1 gets one.
  EXPECT_EQ(select_check_points(hand_errors(), max, {0}, regions, 2, 1, 1e-6), (std::vector<int>{2}));
}

TEST(CheckPoints, SamplesReproducedToRoundingAreIgnored) {
  Eigen::MatrixXf e = hand_errors();
  Eigen::VectorXd max = Eigen::VectorXd::Ones(3);
  // Sample 1 below the noise floor: without it p2 (sum 0.4) loses to p4 (1.05) and p1 (1.0).
  max(1) = 1e-9;
  e.row(1) *= 1e-9f;
  EXPECT_EQ(select_check_points(e, max, {0}, {}, 0, 1, 1e-6), (std::vector<int>{4}));
}

// The greedy step written as its definition, a scan of every point in index order: the point with
// the largest Σ_i max(0, u_ij − c_i), the lowest index on ties.
std::vector<int> greedy_by_scan(const Eigen::MatrixXf& u, const std::vector<int>& keys, int count) {
  std::vector<char> taken(static_cast<size_t>(u.cols()), 0);
  for (int k : keys) taken[static_cast<size_t>(k)] = 1;
  Eigen::VectorXf coverage = Eigen::VectorXf::Zero(u.rows());
  std::vector<int> chosen;
  while (static_cast<int>(chosen.size()) < count) {
    long best = -1;
    float best_gain = -1;
    for (long j = 0; j < u.cols(); ++j) {
      if (taken[static_cast<size_t>(j)]) continue;
      const float gain = (u.col(j) - coverage).cwiseMax(0.0f).sum();
      if (gain > best_gain) {
        best_gain = gain;
        best = j;
      }
    }
    if (best < 0) break;
    chosen.push_back(static_cast<int>(best));
    taken[static_cast<size_t>(best)] = 1;
    coverage = coverage.cwiseMax(u.col(best));
  }
  return chosen;
}

TEST(CheckPoints, TheLazySelectionTakesWhatAFullScanTakes) {
  // Errors on a coarse grid of levels, so that gains tie often, and columns repeated outright.
  std::mt19937 random(7);
  std::uniform_int_distribution<int> level(0, 4);
  for (int trial = 0; trial < 20; ++trial) {
    const long n = 12, N = 40;
    Eigen::MatrixXf e(n, N);
    for (long j = 0; j < N; ++j) {
      for (long i = 0; i < n; ++i) e(i, j) = 0.25f * static_cast<float>(level(random));
    }
    for (long j = 30; j < N; ++j) e.col(j) = e.col(j - 30);
    for (long i = 0; i < n; ++i) e(i, 0) = 1;  // the key: every sample's worst point
    const Eigen::VectorXd max = Eigen::VectorXd::Ones(n);
    const std::vector<int> keys = {0};
    EXPECT_EQ(select_check_points(e, max, keys, {}, 0, 25, 1e-6), greedy_by_scan(e, keys, 25)) << "trial " << trial;
  }
}

// The 16-bit form training keeps (issue #53): an error read back is below the true one by less
// than 2⁻¹⁶ of its sample's largest, never above it.
TEST(RelativePointErrors, AnErrorReadBackIsNeverAboveTheTruthAndWithinOneStep) {
  std::mt19937 random(11);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int trial = 0; trial < 10000; ++trial) {
    const float largest = std::ldexp(unit(random) + 0.5f, static_cast<int>(random() % 40) - 20);
    const float error = trial % 100 == 0 ? largest : unit(random) * largest;
    const double back = RelativePointErrors::error(RelativePointErrors::quantise(error, largest), largest);
    EXPECT_LE(back, static_cast<double>(error) * (1 + 1e-12)) << error << " of " << largest;
    EXPECT_GE(back, static_cast<double>(error) - static_cast<double>(largest) / 65535.0 * (1 + 1e-6));
  }
  EXPECT_EQ(RelativePointErrors::quantise(2.0f, 2.0f), 65535);
  EXPECT_EQ(RelativePointErrors::quantise(0.0f, 2.0f), 0);
}

// The selection on the 16-bit form takes what the greedy step's definition takes (a full scan,
// here in the form's own integer units, where sums are exact and ties tie), over the rows counted
// and above the noise floor only; levels on a coarse grid, so that gains tie often.
TEST(RelativePointErrors, TheSelectionTakesWhatAFullScanTakesOverTheRowsCounted) {
  std::mt19937 random(5);
  std::uniform_int_distribution<int> level(0, 5);
  for (int trial = 0; trial < 20; ++trial) {
    const long n = 14, N = 40;
    RelativePointErrors errors;
    errors.u.resize(n, N);
    Eigen::VectorXd max = Eigen::VectorXd::Ones(n);
    for (long i = 0; i < n; ++i) {
      for (long j = 0; j < N; ++j) {
        errors.u(i, j) = j == 0 ? 65535 : static_cast<std::uint16_t>(13107 * level(random));  // 65535 / 5
      }
    }
    // Rows 3 and 9 not counted; row 5 below the noise floor.
    std::vector<char> counted(static_cast<size_t>(n), 1);
    counted[3] = counted[9] = 0;
    max(5) = 1e-9;
    Eigen::MatrixXf judged(n - 3, N);
    for (long i = 0, row = 0; i < n; ++i) {
      if (i != 3 && i != 5 && i != 9) judged.row(row++) = errors.u.row(i).cast<float>();
    }
    EXPECT_EQ(select_check_points(errors, counted, max, {0}, {}, 0, 12, 1e-6), greedy_by_scan(judged, {0}, 12))
        << "trial " << trial;
  }
}

}  // namespace
}  // namespace animspace::pmsc
