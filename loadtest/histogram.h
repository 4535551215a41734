// A latency histogram in the manner of HdrHistogram: log-linear buckets (every power of two split
// into 2^kSubBucketBits equal sub-buckets), so that any recorded value is represented within a
// relative error of 2^-kSubBucketBits (< 0.8%) in constant memory, whatever the number of samples
// — unlike a sorted vector of every latency, which a long open-loop run cannot afford.
#pragma once

#include <array>
#include <cstdint>

namespace animspace::loadtest {

class LatencyHistogram {
 public:
  static constexpr int kSubBucketBits = 7;                   // 128 sub-buckets per power of two
  static constexpr int kPowers = 40;                         // 1 ns … 2^40 ns ≈ 18 minutes
  static constexpr int kBuckets = kPowers << kSubBucketBits;

  // Records one latency in nanoseconds (values ≥ 2^40 ns land in the last bucket; negative as 0).
  void record(int64_t nanoseconds);
  void merge(const LatencyHistogram& other);

  uint64_t count() const { return count_; }
  int64_t min() const { return count_ ? min_ : 0; }
  int64_t max() const { return max_; }
  double mean() const { return count_ ? sum_ / static_cast<double>(count_) : 0.0; }
  // The value at quantile q ∈ [0, 1], by nearest rank (clients/cpp/tools/quantile.h, the definition
  // animspace-bench uses on its sorted samples): the bucket holding the k-th smallest sample,
  // k = max(1, ⌈q·count⌉), reported as its midpoint (clamped to [min, max]) — so within the bucket
  // width (< 0.8%) of the exact order statistic tools::quantile would return. 0 when empty.
  int64_t quantile(double q) const;

  // Bucket of a value, and the half-open value range [lower, upper) a bucket covers (exposed for
  // tests).
  static int bucket_of(int64_t nanoseconds);
  static int64_t bucket_lower(int bucket);
  static int64_t bucket_upper(int bucket);

 private:
  std::array<uint64_t, kBuckets> counts_{};
  uint64_t count_ = 0;
  int64_t min_ = INT64_MAX;
  int64_t max_ = 0;
  double sum_ = 0;  // nanoseconds; exact to 2^53 ns (104 days)
};

}  // namespace animspace::loadtest
