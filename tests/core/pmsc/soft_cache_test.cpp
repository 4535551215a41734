#include "core/pmsc/soft_cache.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace animspace::pmsc {
namespace {

TEST(SoftCache, HitBlendMissFollowTheThresholds) {
  const SoftCacheThresholds eps{0.1, 0.15};  // the papers' example
  EXPECT_EQ(decide(0.0, eps).status, CacheStatus::kHit);
  EXPECT_EQ(decide(0.1, eps).status, CacheStatus::kHit);
  EXPECT_EQ(decide(0.1, eps).alpha, 0.0);
  EXPECT_EQ(decide(0.125, eps).status, CacheStatus::kBlend);
  EXPECT_NEAR(decide(0.125, eps).alpha, 0.5, 1e-12);
  EXPECT_EQ(decide(0.15, eps).status, CacheStatus::kMiss);
  EXPECT_EQ(decide(0.15, eps).alpha, 1.0);
  EXPECT_EQ(decide(7.0, eps).alpha, 1.0);
}

TEST(SoftCache, AlphaIsContinuousAcrossBothEnds) {
  const SoftCacheThresholds eps{0.2, 0.7};
  // Approaching each end from inside the zone, α tends to the value outside it (no popping).
  for (double h : {1e-3, 1e-6, 1e-9}) {
    EXPECT_NEAR(decide(0.2 + h, eps).alpha, 0.0, 2 * h / 0.5);
    EXPECT_NEAR(decide(0.7 - h, eps).alpha, 1.0, 2 * h / 0.5);
  }
  // Linear in between: equal steps in e_key give equal steps in α.
  double previous = decide(0.2, eps).alpha;
  for (int i = 1; i <= 50; ++i) {
    const double a = decide(0.2 + 0.01 * i, eps).alpha;
    EXPECT_NEAR(a - previous, 0.02, 1e-9);
    previous = a;
  }
}

TEST(SoftCache, AnErrorThatIsNotANumberIsAMiss) {
  const SoftCacheThresholds eps{0.1, 0.15};
  for (double e : {std::nan(""), std::numeric_limits<double>::infinity()}) {
    EXPECT_EQ(decide(e, eps).status, CacheStatus::kMiss) << e;
    EXPECT_EQ(decide(e, eps).alpha, 1.0) << e;
  }
}

TEST(SoftCache, EmptyZoneIsAHardThreshold) {
  const SoftCacheThresholds eps{0.3, 0.3};
  EXPECT_EQ(decide(0.3, eps).status, CacheStatus::kHit);
  EXPECT_EQ(decide(0.3000001, eps).status, CacheStatus::kMiss);
}

TEST(SoftCache, BlendIsTheConvexCombination) {
  Eigen::VectorXf estimate(3), full(3), out(3);
  estimate << 0, 10, -4;
  full << 2, 10, 4;
  blend(estimate, full, 0.25, out);
  EXPECT_FLOAT_EQ(out(0), 0.5f);
  EXPECT_FLOAT_EQ(out(1), 10.0f);
  EXPECT_FLOAT_EQ(out(2), -2.0f);
}

TEST(SoftCache, ValidationNamesTheField) {
  EXPECT_TRUE(validate({0.1, 0.2}).ok());
  auto inverted = validate({0.2, 0.1});
  ASSERT_FALSE(inverted.ok());
  EXPECT_NE(inverted.error().message.find("epsilon_max"), std::string::npos);
  auto negative = validate({-1, 0.1});
  ASSERT_FALSE(negative.ok());
  EXPECT_NE(negative.error().message.find("epsilon_min"), std::string::npos);
  EXPECT_FALSE(validate({0.1, std::nan("")}).ok());
}

}  // namespace
}  // namespace animspace::pmsc
