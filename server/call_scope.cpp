#include "server/call_scope.h"

#include <spdlog/spdlog.h>

namespace animspace::server {

CallScope::~CallScope() {
  if (!finished_) metrics_.call_finished();
}

grpc::Status CallScope::finish(grpc::Status status) {
  finished_ = true;
  metrics_.call_finished();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const int code = static_cast<int>(status.error_code());
  metrics_.record_call(rpc_, model_, code, seconds);
  if (!status.ok()) {
    spdlog::warn("rpc={} model={} status={} message=\"{}\" seconds={:.6f}", rpc_,
                 model_.empty() ? "-" : model_, grpc_code_name(code), status.error_message(), seconds);
  } else {
    spdlog::debug("rpc={} model={} status=OK seconds={:.6f}", rpc_, model_.empty() ? "-" : model_, seconds);
  }
  return status;
}

}  // namespace animspace::server
