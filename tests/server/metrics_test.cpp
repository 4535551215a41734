#include "server/metrics.h"

#include <gtest/gtest.h>

namespace animspace::server {
namespace {

TEST(Histogram, BucketsFollowPrometheusUpperBounds) {
  Histogram h({1.0, 2.0, 4.0});
  for (double v : {0.5, 1.0, 1.5, 2.0, 3.0, 5.0}) h.observe(v);
  // ≤1: {0.5, 1.0}; (1,2]: {1.5, 2.0}; (2,4]: {3.0}; +Inf: {5.0}
  EXPECT_EQ(h.counts(), (std::vector<uint64_t>{2, 2, 1, 1}));
  EXPECT_EQ(h.total_count(), 6u);
  EXPECT_DOUBLE_EQ(h.sum(), 13.0);
}

TEST(Histogram, QuantileInterpolatesInsideTheBucket) {
  Histogram h({10.0, 20.0});
  for (int i = 0; i < 4; ++i) h.observe(15.0);  // all in (10, 20]
  // Rank 0.5·4 = 2 of 4 observations in the bucket: halfway from 10 to 20.
  EXPECT_DOUBLE_EQ(h.quantile(0.5), 15.0);
  EXPECT_DOUBLE_EQ(h.quantile(1.0), 20.0);
  EXPECT_DOUBLE_EQ(h.quantile(0.25), 12.5);
}

TEST(Histogram, EmptyQuantileIsZero) {
  Histogram h({1.0});
  EXPECT_EQ(h.quantile(0.99), 0.0);
}

TEST(Metrics, CountsCallsPerModelAndRendersPrometheusText) {
  Metrics metrics;
  metrics.record_call("ModelService/DescribeModel", "arm", 0, 0.001);
  metrics.record_call("ModelService/DescribeModel", "arm", 5, 0.002);
  metrics.record_pose("arm", pmsc::CacheStatus::kHit, 1e-4);
  metrics.record_pose("arm", pmsc::CacheStatus::kMiss, 0.3);
  const auto stats = metrics.model_statistics();
  ASSERT_TRUE(stats.count("arm"));
  EXPECT_EQ(stats.at("arm").requests, 2u);
  EXPECT_EQ(stats.at("arm").errors, 1u);
  EXPECT_EQ(stats.at("arm").poses, 2u);
  EXPECT_EQ(stats.at("arm").hits, 1u);
  EXPECT_EQ(stats.at("arm").misses, 1u);

  const std::string text = metrics.prometheus_text();
  EXPECT_NE(text.find("animspace_requests_total{rpc=\"ModelService/DescribeModel\",model=\"arm\",code=\"NOT_FOUND\"} 1"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("animspace_cache_hits_total{model=\"arm\"} 1"), std::string::npos) << text;
  // Cumulative buckets end with +Inf equal to the count.
  EXPECT_NE(text.find("animspace_request_duration_seconds_bucket{rpc=\"ModelService/DescribeModel\",le=\"+Inf\"} 2"),
            std::string::npos)
      << text;
  metrics.reset_model_statistics("arm");
  EXPECT_FALSE(metrics.model_statistics().count("arm"));
}

TEST(Metrics, GrpcCodeNames) {
  EXPECT_STREQ(grpc_code_name(0), "OK");
  EXPECT_STREQ(grpc_code_name(3), "INVALID_ARGUMENT");
  EXPECT_STREQ(grpc_code_name(16), "UNAUTHENTICATED");
  EXPECT_STREQ(grpc_code_name(99), "UNKNOWN");
}

}  // namespace
}  // namespace animspace::server
