// The nearest-rank quantile against cases worked by hand from its definition: the q-quantile of
// n samples is the k-th smallest, k = max(1, ⌈q·n⌉).
#include "clients/cpp/tools/quantile.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::tools {
namespace {

TEST(Quantile, FourSamplesWorkedByHand) {
  // Given out of order: the definition is on the sorted samples 10, 20, 30, 40.
  const std::vector<double> samples{30, 10, 40, 20};
  struct Case {
    double q;
    double expected;  // ⌈q·4⌉-th smallest
  };
  for (const Case& c : {Case{0.0, 10},    // k = max(1, 0) = 1
                        Case{0.25, 10},   // k = ⌈1⌉ = 1
                        Case{0.26, 20},   // k = ⌈1.04⌉ = 2
                        Case{0.5, 20},    // k = 2: a measured value, where interpolation gives 25
                        Case{0.75, 30},   // k = 3
                        Case{0.76, 40},   // k = ⌈3.04⌉ = 4
                        Case{0.99, 40},   // k = ⌈3.96⌉ = 4
                        Case{1.0, 40}}) {
    EXPECT_EQ(quantile(samples, c.q), c.expected) << "q = " << c.q;
  }
}

TEST(Quantile, OddCountMedianIsTheMiddleSample) {
  EXPECT_EQ(quantile({5, 1, 3}, 0.5), 3);     // k = ⌈1.5⌉ = 2
  EXPECT_EQ(quantile({9, 9, 1, 9}, 0.5), 9);  // sorted 1 9 9 9, k = 2: ties count once each
  EXPECT_EQ(quantile({7}, 0.0), 7);
  EXPECT_EQ(quantile({7}, 0.99), 7);
}

// 1, 2, …, 100: the k/100-quantile is k for every k. q = 0.07 is the trap — 0.07 × 100 evaluates to
// 7.000000000000001 in doubles, and a bare ⌈·⌉ would answer 8.
TEST(Quantile, PercentilesOfOneToHundredAreTheirOwnRank) {
  std::vector<double> samples;
  for (int v = 100; v >= 1; --v) samples.push_back(v);
  for (int k = 1; k <= 100; ++k) EXPECT_EQ(quantile(samples, k / 100.0), k) << "q = " << k << "/100";
}

TEST(Quantile, NoSamplesHaveNoQuantile) { EXPECT_TRUE(std::isnan(quantile({}, 0.5))); }

TEST(NearestRank, RanksWorkedByHand) {
  EXPECT_EQ(nearest_rank(0.0, 5), 1u);
  EXPECT_EQ(nearest_rank(0.2, 5), 1u);   // ⌈1⌉
  EXPECT_EQ(nearest_rank(0.21, 5), 2u);  // ⌈1.05⌉
  EXPECT_EQ(nearest_rank(1.0, 5), 5u);
  EXPECT_EQ(nearest_rank(0.999, 1000), 999u);
  EXPECT_EQ(nearest_rank(0.9991, 1000), 1000u);  // ⌈999.1⌉
  EXPECT_EQ(nearest_rank(0.5, 1), 1u);
}

}  // namespace
}  // namespace animspace::tools
