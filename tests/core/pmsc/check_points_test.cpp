// Check point selection (issue #35, core/pmsc/check_points.h) on hand-worked cases.
#include "core/pmsc/check_points.h"

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

}  // namespace
}  // namespace animspace::pmsc
