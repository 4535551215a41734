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

}  // namespace animspace::server
