#include "server/model_lookup.h"

#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {

grpc::Status find_model(const ModelRegistry& registry, const v1::ModelRef& ref, std::string_view field,
                        std::shared_ptr<const LoadedModel>& out, const CallControl* call) {
  if (grpc::Status valid = check_model_ref(ref, field); !valid.ok()) return valid;
  auto found = registry.find(ref.name(), ref.version());
  if (!found) return to_grpc_status(found.error());
  out = std::move(*found);
  if (call != nullptr) call->set_model(out->name);
  return grpc::Status::OK;
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
