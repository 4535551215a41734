// Counters and histograms for operators: scraped as Prometheus text (GET /metrics) and read by
// StatsService. One mutex guards everything: updates are a few additions per call, far below
// the cost of the call itself.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/pmsc/soft_cache.h"

namespace animspace::server {

// Fixed-bound histogram (Prometheus semantics: bucket i counts values ≤ bounds[i]; one more
// bucket for +Inf).
class Histogram {
 public:
  explicit Histogram(std::vector<double> upper_bounds);
  void observe(double value);
  // Linear interpolation inside the bucket that holds quantile q ∈ [0, 1] (as Prometheus's
  // histogram_quantile does), over the part of the bucket that observations reached: never below
  // the smallest value observed nor above the largest (one request of 101 ms is p50 = p99 =
  // 101 ms, not a point inside its bucket). 0 when empty.
  double quantile(double q) const;
  double min() const { return min_; }
  double max() const { return max_; }

  const std::vector<double>& upper_bounds() const { return bounds_; }
  const std::vector<uint64_t>& counts() const { return counts_; }
  uint64_t total_count() const { return total_; }
  double sum() const { return sum_; }

 private:
  std::vector<double> bounds_;
  std::vector<uint64_t> counts_;  // bounds_.size() + 1
  uint64_t total_ = 0;
  double sum_ = 0;
  double min_ = 0;  // of the values observed (0 when none)
  double max_ = 0;
};

// Latency buckets: 50 µs … 10 s, roughly ×2.5 apart.
std::vector<double> latency_bounds_seconds();
// Key-point error buckets, model units: 1e-6 … 10, decades with 1-2.5-5 steps.
std::vector<double> key_point_error_bounds();

struct ModelStatistics {
  uint64_t requests = 0;
  uint64_t errors = 0;
  uint64_t poses = 0;  // key-point poses through the soft cache and skeleton poses
  uint64_t hits = 0;
  uint64_t blends = 0;
  uint64_t misses = 0;
  Histogram latency_seconds{latency_bounds_seconds()};
  Histogram key_point_error{key_point_error_bounds()};
};

class Metrics {
 public:
  Metrics();

  // One finished call. `model` is empty for calls that name none. `code` is the gRPC code.
  void record_call(std::string_view rpc, std::string_view model, int code, double seconds);
  // One pose through the soft cache.
  void record_pose(std::string_view model, pmsc::CacheStatus status, double key_point_error);
  // A blend or miss served but not appended to the model's miss log, and why: the request set
  // skip_miss_log (test traffic), the log reached --miss-log-max-bytes, or the append failed.
  enum class NotLogged { kSkipped, kFull, kError };
  void record_miss_not_logged(std::string_view model, NotLogged reason);
  // The size of the model's miss log file after an append (animspace_miss_log_bytes).
  void set_miss_log_bytes(std::string_view model, uint64_t bytes);
  // Skeleton poses evaluated (SkinningService): counted as poses, with no verdict.
  void record_skeleton_poses(std::string_view model, uint64_t count);
  void set_models_loaded(int count);
  // The registry's memory under --memory-budget (ModelRegistry::memory): budget (0 = none),
  // bytes resident, and versions evicted and loaded again since start.
  void set_registry_memory(uint64_t budget_bytes, uint64_t resident_bytes, uint64_t evictions, uint64_t reloads);
  // Versions serving now, per model, and the default of each (animspace_model_versions).
  struct ServedVersion {
    std::string model;
    uint64_t version = 0;
    bool is_default = false;
  };
  void set_served_versions(std::vector<ServedVersion> versions);

  // Calls whose handler is running (CallScope brackets every handler).
  void call_started() { in_flight_.fetch_add(1, std::memory_order_relaxed); }
  void call_finished() { in_flight_.fetch_sub(1, std::memory_order_relaxed); }
  int64_t calls_in_flight() const { return in_flight_.load(std::memory_order_relaxed); }

  std::map<std::string, ModelStatistics> model_statistics() const;
  void reset_model_statistics(std::string_view model);  // empty: all
  std::chrono::system_clock::time_point statistics_since() const;

  // The Prometheus text exposition format, version 0.0.4.
  std::string prometheus_text() const;

 private:
  struct CallKey {
    std::string rpc;
    std::string model;
    int code;
    auto operator<=>(const CallKey&) const = default;
  };

  mutable std::mutex mutex_;
  std::map<CallKey, uint64_t> calls_;
  std::map<std::string, Histogram> rpc_latency_;
  std::map<std::string, ModelStatistics> models_;
  std::chrono::system_clock::time_point since_;
  int models_loaded_ = 0;
  uint64_t memory_budget_bytes_ = 0;
  uint64_t resident_bytes_ = 0;
  uint64_t evictions_ = 0;
  uint64_t reloads_ = 0;
  std::vector<ServedVersion> served_versions_;
  // Not reset with the statistics: Prometheus counters only grow.
  std::map<std::pair<std::string, NotLogged>, uint64_t> not_logged_;
  std::map<std::string, uint64_t> miss_log_bytes_;
  std::atomic<int64_t> in_flight_{0};
};

// Name of a gRPC status code as Prometheus labels and logs show it ("NOT_FOUND").
const char* grpc_code_name(int code);

}  // namespace animspace::server
