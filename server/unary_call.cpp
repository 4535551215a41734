#include "server/unary_call.h"

#include "server/status_mapping.h"

namespace animspace::server {

grpc::Status CallControl::stop_status() const {
  if (context_->IsCancelled()) return {grpc::StatusCode::CANCELLED, "the client cancelled the call"};
  if (std::chrono::system_clock::now() >= context_->deadline()) {
    return {grpc::StatusCode::DEADLINE_EXCEEDED, "the call's deadline passed before the work was done"};
  }
  return grpc::Status::OK;
}

grpc::Status admit(ServiceEnvironment& env, const grpc::CallbackServerContext* context, std::string_view rpc,
                   Access access, std::shared_ptr<Admission::Ticket>* ticket) {
  const std::string method = "animspace.v1." + std::string(rpc);
  if (grpc::Status auth = env.authenticator.check(context->client_metadata(), access, method); !auth.ok()) {
    return auth;
  }
  *ticket = env.admission.try_admit();
  if (!*ticket) {
    return resource_exhausted("server busy: " + std::to_string(env.admission.limit()) +
                              " calls are already in progress (--max-concurrent-calls); retry with backoff");
  }
  return grpc::Status::OK;
}

}  // namespace animspace::server
