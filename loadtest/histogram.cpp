#include "loadtest/histogram.h"

#include <algorithm>
#include <bit>

#include "clients/cpp/tools/quantile.h"

namespace animspace::loadtest {
namespace {

constexpr int64_t kSub = int64_t{1} << LatencyHistogram::kSubBucketBits;

}  // namespace

// Values below 2^kSubBucketBits have a bucket each (exact). Above, a value with its highest set
// bit at position p ≥ kSubBucketBits is in power band p − kSubBucketBits + 1, at sub-bucket
// (value >> (p − kSubBucketBits)) − kSub, so each band's buckets are 2^(p − kSubBucketBits) wide.
int LatencyHistogram::bucket_of(int64_t nanoseconds) {
  const int64_t v = std::max<int64_t>(0, nanoseconds);
  if (v < kSub) return static_cast<int>(v);
  const int p = 63 - std::countl_zero(static_cast<uint64_t>(v));
  const int band = p - kSubBucketBits + 1;
  const int64_t sub = (v >> (p - kSubBucketBits)) - kSub;
  const int bucket = (band << kSubBucketBits) + static_cast<int>(sub);
  return std::min(bucket, kBuckets - 1);
}

int64_t LatencyHistogram::bucket_lower(int bucket) {
  const int band = bucket >> kSubBucketBits;
  const int64_t sub = bucket & (kSub - 1);
  if (band == 0) return sub;
  return (kSub + sub) << (band - 1);
}

int64_t LatencyHistogram::bucket_upper(int bucket) {
  const int band = bucket >> kSubBucketBits;
  if (band == 0) return bucket_lower(bucket) + 1;
  return bucket_lower(bucket) + (int64_t{1} << (band - 1));
}

void LatencyHistogram::record(int64_t nanoseconds) {
  const int64_t v = std::max<int64_t>(0, nanoseconds);
  ++counts_[static_cast<size_t>(bucket_of(v))];
  ++count_;
  min_ = std::min(min_, v);
  max_ = std::max(max_, v);
  sum_ += static_cast<double>(v);
}

void LatencyHistogram::merge(const LatencyHistogram& other) {
  for (size_t b = 0; b < counts_.size(); ++b) counts_[b] += other.counts_[b];
  count_ += other.count_;
  min_ = std::min(min_, other.min_);
  max_ = std::max(max_, other.max_);
  sum_ += other.sum_;
}

int64_t LatencyHistogram::quantile(double q) const {
  if (count_ == 0) return 0;
  const uint64_t rank = tools::nearest_rank(q, count_);
  uint64_t seen = 0;
  for (int b = 0; b < kBuckets; ++b) {
    seen += counts_[static_cast<size_t>(b)];
    if (seen >= rank) {
      const int64_t mid = bucket_lower(b) + (bucket_upper(b) - bucket_lower(b) - 1) / 2;
      return std::clamp(mid, min_, max_);
    }
  }
  return max_;
}

}  // namespace animspace::loadtest
