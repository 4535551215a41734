#include "server/model_lookup.h"

#include <algorithm>
#include <utility>

#include "core/common/nearest_names.h"
#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {

grpc::Status find_model(ModelRegistry& registry, const v1::ModelRef& ref, std::string_view field,
                        std::shared_ptr<const LoadedModel>& out, const CallControl* call,
                        std::chrono::system_clock::time_point deadline) {
  if (grpc::Status valid = check_model_ref(ref, field); !valid.ok()) return valid;
  if (call != nullptr && call->context() != nullptr) deadline = std::min(deadline, call->context()->deadline());
  ReloadHint reloading;
  auto found = registry.find(ref.name(), ref.version(), deadline, &reloading);
  if (!found) {
    if (reloading.after.count() > 0) {
      // gRPC's client retry policy waits this long before its next attempt (gRFC A6 pushback).
      if (call != nullptr && call->context() != nullptr) {
        call->context()->AddTrailingMetadata("grpc-retry-pushback-ms", std::to_string(reloading.after.count()));
      }
      return {grpc::StatusCode::UNAVAILABLE, found.error().message};
    }
    // A wrong version already lists the versions; a wrong name gets the names.
    if (found.error().code == ErrorCode::kNotFound && !registry.describe(ref.name())) {
      return unknown_model(registry, ref.name());
    }
    return to_grpc_status(found.error());
  }
  out = std::move(*found);
  if (call != nullptr) call->set_model(out->name);
  return grpc::Status::OK;
}

grpc::Status unknown_model(const ModelRegistry& registry, std::string_view name) {
  std::vector<std::string> served;
  for (const auto& entry : registry.list()) served.push_back(entry.name);
  std::string message = "model '" + std::string(name) + "' is not loaded";
  // Issue #54: during start-up the model may only not be loaded yet. UNAVAILABLE is what a client
  // retries (the health check says NOT_SERVING meanwhile); NOT_FOUND would be final.
  if (!registry.repository_loaded()) {
    return {grpc::StatusCode::UNAVAILABLE,
            message + " yet: the server is still loading its repository (health NOT_SERVING); retry"};
  }
  if (served.empty()) return not_found(message + "; the server serves no models");
  const std::vector<std::string> near = nearest_names(name, served);
  for (size_t k = 0; k < near.size(); ++k) {
    message += (k == 0 ? "; did you mean '" : k + 1 == near.size() ? " or '" : ", '") + near[k] + "'";
  }
  message += near.empty() ? "; models: " : "? models: ";
  constexpr size_t kListed = 20;
  for (size_t i = 0; i < served.size() && i < kListed; ++i) message += (i == 0 ? "" : ", ") + served[i];
  if (served.size() > kListed) message += ", … (" + std::to_string(served.size() - kListed) + " more)";
  return not_found(message);
}

grpc::Status unsupported_by_kind(const LoadedModel& model, std::string_view reason) {
  return {grpc::StatusCode::FAILED_PRECONDITION, "model '" + model.name + "' version " + std::to_string(model.version) +
                                                     " is of kind " + container::kind_name(model.info.kind) + ": " +
                                                     std::string(reason)};
}

grpc::Status require_skeleton(const LoadedModel& model, std::string_view reason) {
  if (model.animation_space) return grpc::Status::OK;
  return {grpc::StatusCode::FAILED_PRECONDITION, "model '" + model.name + "' version " + std::to_string(model.version) +
                                                     " is of kind " + container::kind_name(model.info.kind) +
                                                     " and has no skeleton: " + std::string(reason)};
}

}  // namespace animspace::server
