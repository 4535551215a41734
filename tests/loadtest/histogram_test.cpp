// The load tester's latency histogram against the exact order statistics of the same samples,
// and the open-loop schedule against the integral it inverts.
#include "loadtest/histogram.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "clients/cpp/tools/quantile.h"
#include "loadtest/runner.h"

namespace animspace::loadtest {
namespace {

// The exact q-quantile in the same convention: the ⌈q·n⌉-th smallest sample.
int64_t exact_quantile(std::vector<int64_t> sorted, double q) {
  const auto rank = std::max<size_t>(1, static_cast<size_t>(std::ceil(q * static_cast<double>(sorted.size()))));
  return sorted[rank - 1];
}

TEST(LatencyHistogram, BucketsTileTheLineWithBoundedRelativeWidth) {
  int64_t expected_lower = 0;
  for (int b = 0; b < LatencyHistogram::kBuckets - 1; ++b) {
    ASSERT_EQ(LatencyHistogram::bucket_lower(b), expected_lower) << "bucket " << b;
    const int64_t upper = LatencyHistogram::bucket_upper(b);
    ASSERT_GT(upper, expected_lower);
    // Width relative to the values it holds: exact below 128 ns, under 1/128 above.
    if (expected_lower >= 128) {
      EXPECT_LE(static_cast<double>(upper - expected_lower) / static_cast<double>(expected_lower), 1.0 / 128 + 1e-12);
    }
    EXPECT_EQ(LatencyHistogram::bucket_of(expected_lower), b);
    EXPECT_EQ(LatencyHistogram::bucket_of(upper - 1), b);
    expected_lower = upper;
  }
}

TEST(LatencyHistogram, QuantilesMatchTheSortedSamplesWithinOnePercent) {
  std::mt19937_64 rng(42);
  // Log-normal latencies around 2 ms with a heavy tail, as a loaded server gives.
  std::lognormal_distribution<double> latency(std::log(2e6), 0.8);
  std::vector<int64_t> samples;
  LatencyHistogram h;
  for (int i = 0; i < 200000; ++i) {
    const auto v = static_cast<int64_t>(latency(rng));
    samples.push_back(v);
    h.record(v);
  }
  std::sort(samples.begin(), samples.end());
  ASSERT_EQ(h.count(), samples.size());
  EXPECT_EQ(h.min(), samples.front());
  EXPECT_EQ(h.max(), samples.back());
  double mean = 0;
  for (int64_t v : samples) mean += static_cast<double>(v) / static_cast<double>(samples.size());
  EXPECT_NEAR(h.mean(), mean, 1e-9 * mean);
  for (double q : {0.0, 0.01, 0.5, 0.9, 0.99, 0.999, 0.9999, 1.0}) {
    const double exact = static_cast<double>(exact_quantile(samples, q));
    EXPECT_NEAR(static_cast<double>(h.quantile(q)), exact, 0.01 * exact) << "q = " << q;
  }
}

// Below 128 ns every bucket holds one value, so the histogram's quantile is exact there and must
// be the very sample the bench's sorted-sample quantile picks: one definition, not two.
TEST(LatencyHistogram, QuantilesAreTheBenchsNearestRankWhereBucketsAreExact) {
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<int64_t> value(0, 127);
  for (int n : {1, 2, 3, 10, 70, 100, 1000}) {
    LatencyHistogram h;
    std::vector<double> samples;
    for (int i = 0; i < n; ++i) {
      const int64_t v = value(rng);
      h.record(v);
      samples.push_back(static_cast<double>(v));
    }
    for (int percent = 0; percent <= 100; ++percent) {
      const double q = percent / 100.0;
      EXPECT_EQ(static_cast<double>(h.quantile(q)), tools::quantile(samples, q)) << "n = " << n << ", q = " << q;
    }
  }
}

TEST(LatencyHistogram, MergingEqualsRecordingEverything) {
  LatencyHistogram a, b, all;
  for (int64_t v = 1; v < 5000000; v = v * 3 / 2 + 7) {
    ((v % 2) ? a : b).record(v);
    all.record(v);
  }
  a.merge(b);
  EXPECT_EQ(a.count(), all.count());
  EXPECT_EQ(a.min(), all.min());
  EXPECT_EQ(a.max(), all.max());
  for (double q : {0.1, 0.5, 0.99}) EXPECT_EQ(a.quantile(q), all.quantile(q));
  EXPECT_EQ(LatencyHistogram().quantile(0.5), 0);
}

TEST(OpenLoopSchedule, ConstantRateIsEvenlySpaced) {
  for (uint64_t k : {0u, 1u, 10u, 999u}) EXPECT_DOUBLE_EQ(scheduled_time(k, 200, 200, 10), static_cast<double>(k) / 200);
}

TEST(OpenLoopSchedule, LinearRampPlacesRequestKWhereTheRateIntegratesToK) {
  const double r0 = 50, r1 = 450, T = 4;  // 1000 requests in all: (50 + 450) / 2 · 4
  double previous = -1;
  for (uint64_t k = 0; k < 1000; k += 37) {
    const double t = scheduled_time(k, r0, r1, T);
    ASSERT_GT(t, previous);
    previous = t;
    // ∫₀ᵗ (r0 + (r1 − r0) s / T) ds, by the trapezoid rule on a fine grid (independent of the inversion).
    double integral = 0;
    const int n = 20000;
    for (int i = 0; i < n; ++i) {
      const double s0 = t * i / n, s1 = t * (i + 1) / n;
      integral += 0.5 * ((r0 + (r1 - r0) * s0 / T) + (r0 + (r1 - r0) * s1 / T)) * (s1 - s0);
    }
    EXPECT_NEAR(integral, static_cast<double>(k), 1e-6 * std::max<double>(1, static_cast<double>(k)));
  }
  EXPECT_NEAR(scheduled_time(1000, r0, r1, T), T, 1e-9);
  // Ramping down: requests beyond what the ramp ever reaches are never due.
  EXPECT_TRUE(std::isinf(scheduled_time(100000, 400, 0, 1)));
}

}  // namespace
}  // namespace animspace::loadtest
