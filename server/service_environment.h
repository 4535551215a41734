// What every service handler shares: the registry, the metrics, the configuration, the pools
// that run the work, admission control, authentication and the miss logs.
#pragma once

#include <chrono>

#include "server/admission.h"
#include "server/auth.h"
#include "server/metrics.h"
#include "server/miss_logs.h"
#include "server/model_registry.h"
#include "server/options.h"
#include "server/pose_batcher.h"
#include "server/render_thread.h"
#include "server/work_pool.h"

namespace animspace::server {

struct ServiceEnvironment {
  ModelRegistry& registry;
  Metrics& metrics;
  const ServerOptions& options;
  // Evaluation and every other short request.
  WorkPool& request_pool;
  // Loading and retraining: seconds of work that must not hold up evaluation threads.
  WorkPool& admin_pool;
  Admission& admission;
  const Authenticator& authenticator;
  MissLogs& miss_logs;
  // Dynamic batching of the poses waiting for one model version.
  PoseBatcher& batcher;
  // The thread that owns the EGL context; null when the server draws no thumbnails, and then
  // `renderer_unavailable` says why.
  RenderThread* renderer = nullptr;
  std::string renderer_unavailable = {};
  std::chrono::system_clock::time_point started_at = std::chrono::system_clock::now();
};

// Publishes what the registry serves now to the metrics (after every load, unload, poll, retrain).
inline void refresh_model_gauges(ServiceEnvironment& env) {
  std::vector<Metrics::ServedVersion> served;
  int count = 0;
  for (const auto& entry : env.registry.list()) {
    const uint64_t default_version = entry.default_version();
    for (const auto& [version, v] : entry.versions) {
      if (!v.servable()) continue;
      served.push_back({entry.name, version, version == default_version});
      ++count;
    }
  }
  env.metrics.set_models_loaded(count);
  env.metrics.set_served_versions(std::move(served));
}

}  // namespace animspace::server
