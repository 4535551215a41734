#include "server/metrics.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

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
  for (int i = 0; i < 4; ++i) h.observe(15.0);  // all in (10, 20], and all 15
  // Every quantile of four equal values is that value: the bucket is narrowed to what was seen.
  EXPECT_DOUBLE_EQ(h.quantile(0.5), 15.0);
  EXPECT_DOUBLE_EQ(h.quantile(1.0), 15.0);
  EXPECT_DOUBLE_EQ(h.quantile(0.25), 15.0);
  // 12 and 18 too: the bucket (10, 20] now holds 12 … 18; rank 0.5·6 = 3 of 6 → halfway, 15.
  h.observe(12.0);
  h.observe(18.0);
  EXPECT_DOUBLE_EQ(h.quantile(0.5), 15.0);
  EXPECT_DOUBLE_EQ(h.quantile(1.0), 18.0);
  EXPECT_DOUBLE_EQ(h.quantile(0.0), 12.0);
}

// Issue #39: one request of 101 ms was reported as p50 175 ms and p99 248.5 ms.
TEST(Histogram, OneObservationIsEveryQuantile) {
  Histogram h(latency_bounds_seconds());
  h.observe(0.101);
  for (double q : {0.0, 0.5, 0.9, 0.99, 1.0}) EXPECT_DOUBLE_EQ(h.quantile(q), 0.101) << "q = " << q;
}

// Against exact quantiles of known samples: the estimate never leaves the observed range and lies
// in the same bucket as the exact ⌈q·n⌉-th smallest value (the most a histogram can know).
TEST(Histogram, QuantilesStayInTheObservedRangeAndTheExactValuesBucket) {
  std::mt19937 rng(39);
  std::lognormal_distribution<double> latency(std::log(0.02), 1.5);
  const std::vector<double> bounds = latency_bounds_seconds();
  for (int n : {1, 2, 3, 10, 101, 5000}) {
    Histogram h(bounds);
    std::vector<double> values;
    for (int i = 0; i < n; ++i) {
      values.push_back(latency(rng));
      h.observe(values.back());
    }
    std::sort(values.begin(), values.end());
    for (double q : {0.0, 0.1, 0.5, 0.9, 0.99, 1.0}) {
      const double estimate = h.quantile(q);
      const auto rank = std::max<size_t>(1, static_cast<size_t>(std::ceil(q * n)));
      const double exact = values[rank - 1];
      EXPECT_GE(estimate, values.front()) << "n = " << n << ", q = " << q;
      EXPECT_LE(estimate, values.back()) << "n = " << n << ", q = " << q;
      const auto bucket = [&](double v) { return std::lower_bound(bounds.begin(), bounds.end(), v) - bounds.begin(); };
      EXPECT_EQ(bucket(estimate), bucket(exact)) << "n = " << n << ", q = " << q << ": " << estimate << " vs " << exact;
    }
  }
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

// Issue #55: a Retrain (or a load) counts among the model's requests but not in its serving
// latency, which a 5 s retrain made read p99 5 s.
TEST(Metrics, AdministrationIsKeptOutOfTheModelsLatency) {
  Metrics metrics;
  metrics.record_call("PoseService/EvaluateKeyPoints", "arm", 0, 0.002);
  metrics.record_call("TrainingService/Retrain", "arm", 0, 5.0);
  metrics.record_call("ModelService/LoadModel", "arm", 0, 0.5);
  const ModelStatistics stats = metrics.model_statistics().at("arm");
  EXPECT_EQ(stats.requests, 3u);
  EXPECT_EQ(stats.latency_seconds.total_count(), 1u);
  EXPECT_LT(stats.latency_seconds.quantile(0.99), 0.01);
}

TEST(Metrics, GrpcCodeNames) {
  EXPECT_STREQ(grpc_code_name(0), "OK");
  EXPECT_STREQ(grpc_code_name(3), "INVALID_ARGUMENT");
  EXPECT_STREQ(grpc_code_name(16), "UNAUTHENTICATED");
  EXPECT_STREQ(grpc_code_name(99), "UNKNOWN");
}

}  // namespace
}  // namespace animspace::server
