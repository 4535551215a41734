// Per-call bookkeeping shared by every RPC handler: latency, the metrics counters, and one log
// line for each failed request (model, RPC, status), as SPEC "Structured logs" asks.
#pragma once

#include <chrono>
#include <string>
#include <string_view>

#include <grpcpp/support/status.h>

#include "server/metrics.h"

namespace animspace::server {

class CallScope {
 public:
  CallScope(Metrics& metrics, std::string_view rpc) : metrics_(metrics), rpc_(rpc) { metrics_.call_started(); }
  ~CallScope();
  CallScope(const CallScope&) = delete;
  CallScope& operator=(const CallScope&) = delete;

  // The model the call is about, once known (labels metrics and log lines).
  void set_model(std::string model) { model_ = std::move(model); }

  // Records the outcome and returns `status` unchanged, so handlers end with
  // `return scope.finish(status);`.
  grpc::Status finish(grpc::Status status);

 private:
  Metrics& metrics_;
  std::string rpc_;
  std::string model_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  bool finished_ = false;
};

}  // namespace animspace::server
