#include "server/metrics.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace animspace::server {
namespace {

// Escapes a Prometheus label value (backslash, double quote, newline).
std::string escape_label(std::string_view value) {
  std::string out;
  for (char c : value) {
    if (c == '\\' || c == '"') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out;
}

void write_histogram(std::ostringstream& out, const std::string& name, const std::string& labels,
                     const Histogram& h) {
  uint64_t cumulative = 0;
  const std::string sep = labels.empty() ? "" : ",";
  for (size_t i = 0; i < h.upper_bounds().size(); ++i) {
    cumulative += h.counts()[i];
    out << name << "_bucket{" << labels << sep << "le=\"" << h.upper_bounds()[i] << "\"} " << cumulative << '\n';
  }
  out << name << "_bucket{" << labels << sep << "le=\"+Inf\"} " << h.total_count() << '\n';
  out << name << "_sum{" << labels << "} " << h.sum() << '\n';
  out << name << "_count{" << labels << "} " << h.total_count() << '\n';
}

}  // namespace

Histogram::Histogram(std::vector<double> upper_bounds)
    : bounds_(std::move(upper_bounds)), counts_(bounds_.size() + 1, 0) {}

void Histogram::observe(double value) {
  const auto it = std::lower_bound(bounds_.begin(), bounds_.end(), value);
  ++counts_[static_cast<size_t>(it - bounds_.begin())];
  min_ = total_ == 0 ? value : std::min(min_, value);
  max_ = total_ == 0 ? value : std::max(max_, value);
  ++total_;
  sum_ += value;
}

double Histogram::quantile(double q) const {
  if (total_ == 0) return 0;
  const double rank = q * static_cast<double>(total_);
  uint64_t cumulative = 0;
  for (size_t i = 0; i < counts_.size(); ++i) {
    const uint64_t before = cumulative;
    cumulative += counts_[i];
    if (static_cast<double>(cumulative) >= rank && counts_[i] > 0) {
      // The bucket's range, narrowed to what was observed: the first bucket holding values starts
      // at the smallest, the last one (+Inf included) ends at the largest.
      const double lower = std::max(i == 0 ? min_ : bounds_[i - 1], min_);
      const double upper = std::min(i == bounds_.size() ? max_ : bounds_[i], max_);
      const double fraction = (rank - static_cast<double>(before)) / static_cast<double>(counts_[i]);
      return std::clamp(lower + (upper - lower) * std::clamp(fraction, 0.0, 1.0), min_, max_);
    }
  }
  return max_;
}

std::vector<double> latency_bounds_seconds() {
  return {50e-6, 100e-6, 250e-6, 500e-6, 1e-3, 2.5e-3, 5e-3, 10e-3, 25e-3, 50e-3, 100e-3, 250e-3,
          500e-3, 1.0, 2.5, 5.0, 10.0};
}

std::vector<double> key_point_error_bounds() {
  std::vector<double> bounds;
  for (int exponent = -6; exponent <= 0; ++exponent) {
    const double decade = std::pow(10.0, exponent);
    bounds.insert(bounds.end(), {decade, 2.5 * decade, 5 * decade});
  }
  bounds.push_back(10.0);
  return bounds;
}

Metrics::Metrics() : since_(std::chrono::system_clock::now()) {}

namespace {

// Calls that administer a model (load, unload, describe, retrain) rather than serve it: counted
// among its requests, kept out of its serving latency (issue #55: one Retrain read as a 5 s p99).
bool administers(std::string_view rpc) {
  return rpc.starts_with("ModelService/") || rpc.starts_with("TrainingService/");
}

}  // namespace

void Metrics::record_call(std::string_view rpc, std::string_view model, int code, double seconds) {
  std::lock_guard lock(mutex_);
  ++calls_[CallKey{std::string(rpc), std::string(model), code}];
  rpc_latency_.try_emplace(std::string(rpc), latency_bounds_seconds()).first->second.observe(seconds);
  if (!model.empty()) {
    auto& stats = models_[std::string(model)];
    ++stats.requests;
    if (code != 0) ++stats.errors;
    if (!administers(rpc)) stats.latency_seconds.observe(seconds);
  }
}

void Metrics::record_pose(std::string_view model, pmsc::CacheStatus status, double key_point_error) {
  std::lock_guard lock(mutex_);
  auto& stats = models_[std::string(model)];
  ++stats.poses;
  switch (status) {
    case pmsc::CacheStatus::kHit: ++stats.hits; break;
    case pmsc::CacheStatus::kBlend: ++stats.blends; break;
    case pmsc::CacheStatus::kMiss: ++stats.misses; break;
  }
  stats.key_point_error.observe(key_point_error);
}

void Metrics::record_skeleton_poses(std::string_view model, uint64_t count) {
  std::lock_guard lock(mutex_);
  models_[std::string(model)].poses += count;
}

void Metrics::set_models_loaded(int count) {
  std::lock_guard lock(mutex_);
  models_loaded_ = count;
}

void Metrics::set_served_versions(std::vector<ServedVersion> versions) {
  std::lock_guard lock(mutex_);
  served_versions_ = std::move(versions);
}

std::map<std::string, ModelStatistics> Metrics::model_statistics() const {
  std::lock_guard lock(mutex_);
  return models_;
}

void Metrics::reset_model_statistics(std::string_view model) {
  std::lock_guard lock(mutex_);
  if (model.empty()) {
    models_.clear();
    since_ = std::chrono::system_clock::now();
  } else {
    models_.erase(std::string(model));
  }
}

void Metrics::record_miss_not_logged(std::string_view model, NotLogged reason) {
  std::lock_guard lock(mutex_);
  ++not_logged_[{std::string(model), reason}];
}

void Metrics::set_registry_memory(uint64_t budget_bytes, uint64_t resident_bytes, uint64_t evictions,
                                  uint64_t reloads) {
  std::lock_guard lock(mutex_);
  memory_budget_bytes_ = budget_bytes;
  resident_bytes_ = resident_bytes;
  evictions_ = evictions;
  reloads_ = reloads;
}

void Metrics::set_miss_log_bytes(std::string_view model, uint64_t bytes) {
  std::lock_guard lock(mutex_);
  miss_log_bytes_[std::string(model)] = bytes;
}

std::chrono::system_clock::time_point Metrics::statistics_since() const {
  std::lock_guard lock(mutex_);
  return since_;
}

std::string Metrics::prometheus_text() const {
  std::lock_guard lock(mutex_);
  std::ostringstream out;
  out << "# HELP animspace_models_loaded Model versions serving: loaded, or evicted under --memory-budget and loaded again on request.\n"
      << "# TYPE animspace_models_loaded gauge\n"
      << "animspace_models_loaded " << models_loaded_ << '\n'
      << "# HELP animspace_calls_in_flight RPC handlers running now.\n"
      << "# TYPE animspace_calls_in_flight gauge\n"
      << "animspace_calls_in_flight " << calls_in_flight() << '\n'
      << "# HELP animspace_registry_resident_bytes Heap held by the model versions loaded now, as measured at their loads.\n"
      << "# TYPE animspace_registry_resident_bytes gauge\n"
      << "animspace_registry_resident_bytes " << resident_bytes_ << '\n'
      << "# HELP animspace_registry_memory_budget_bytes --memory-budget (0: none).\n"
      << "# TYPE animspace_registry_memory_budget_bytes gauge\n"
      << "animspace_registry_memory_budget_bytes " << memory_budget_bytes_ << '\n'
      << "# HELP animspace_registry_evictions_total Versions unloaded to keep within --memory-budget.\n"
      << "# TYPE animspace_registry_evictions_total counter\n"
      << "animspace_registry_evictions_total " << evictions_ << '\n'
      << "# HELP animspace_registry_reloads_total Evicted versions loaded again on request.\n"
      << "# TYPE animspace_registry_reloads_total counter\n"
      << "animspace_registry_reloads_total " << reloads_ << '\n';
  out << "# HELP animspace_model_version_serving Model versions loaded and serving (1 each); default=\"1\" "
         "marks the version a request for version 0 gets.\n"
      << "# TYPE animspace_model_version_serving gauge\n";
  for (const auto& served : served_versions_) {
    out << "animspace_model_version_serving{model=\"" << escape_label(served.model) << "\",version=\""
        << served.version << "\",default=\"" << (served.is_default ? 1 : 0) << "\"} 1\n";
  }

  out << "# HELP animspace_requests_total Finished RPCs by method, model and status code.\n"
      << "# TYPE animspace_requests_total counter\n";
  for (const auto& [key, count] : calls_) {
    out << "animspace_requests_total{rpc=\"" << escape_label(key.rpc) << "\",model=\""
        << escape_label(key.model) << "\",code=\"" << grpc_code_name(key.code) << "\"} " << count << '\n';
  }

  out << "# HELP animspace_request_duration_seconds Server-side RPC latency.\n"
      << "# TYPE animspace_request_duration_seconds histogram\n";
  for (const auto& [rpc, histogram] : rpc_latency_) {
    write_histogram(out, "animspace_request_duration_seconds", "rpc=\"" + escape_label(rpc) + "\"", histogram);
  }

  const std::pair<const char*, uint64_t ModelStatistics::*> cache_counters[] = {
      {"animspace_cache_hits_total", &ModelStatistics::hits},
      {"animspace_cache_blends_total", &ModelStatistics::blends},
      {"animspace_cache_misses_total", &ModelStatistics::misses},
  };
  for (const auto& [name, member] : cache_counters) {
    out << "# TYPE " << name << " counter\n";
    for (const auto& [model, stats] : models_) {
      out << name << "{model=\"" << escape_label(model) << "\"} " << stats.*member << '\n';
    }
  }
  out << "# HELP animspace_misses_not_logged_total Blends and misses served but not in the miss log: "
         "reason skipped (the request set skip_miss_log), full (--miss-log-max-bytes), error (the append failed).\n"
      << "# TYPE animspace_misses_not_logged_total counter\n";
  for (const auto& [key, count] : not_logged_) {
    static constexpr const char* kReasons[] = {"skipped", "full", "error"};
    out << "animspace_misses_not_logged_total{model=\"" << escape_label(key.first) << "\",reason=\""
        << kReasons[static_cast<int>(key.second)] << "\"} " << count << '\n';
  }
  out << "# HELP animspace_miss_log_bytes Size of the model's miss log file (bounded by --miss-log-max-bytes).\n"
      << "# TYPE animspace_miss_log_bytes gauge\n";
  for (const auto& [model, bytes] : miss_log_bytes_) {
    out << "animspace_miss_log_bytes{model=\"" << escape_label(model) << "\"} " << bytes << '\n';
  }
  out << "# HELP animspace_key_point_error Soft-cache key-point RMS error, model units.\n"
      << "# TYPE animspace_key_point_error histogram\n";
  for (const auto& [model, stats] : models_) {
    write_histogram(out, "animspace_key_point_error", "model=\"" + escape_label(model) + "\"",
                    stats.key_point_error);
  }
  return out.str();
}

const char* grpc_code_name(int code) {
  static constexpr const char* kNames[] = {
      "OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "NOT_FOUND",
      "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION", "ABORTED",
      "OUT_OF_RANGE", "UNIMPLEMENTED", "INTERNAL", "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  if (code < 0 || code >= static_cast<int>(std::size(kNames))) return "UNKNOWN";
  return kNames[code];
}

}  // namespace animspace::server
