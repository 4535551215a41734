// What every service handler shares: the registry, the metrics and the configuration.
#pragma once

#include <chrono>

#include "server/metrics.h"
#include "server/model_registry.h"
#include "server/options.h"

namespace animspace::server {

struct ServiceEnvironment {
  ModelRegistry& registry;
  Metrics& metrics;
  const ServerOptions& options;
  std::chrono::system_clock::time_point started_at = std::chrono::system_clock::now();
};

}  // namespace animspace::server
