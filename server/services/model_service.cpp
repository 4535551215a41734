#include "server/services/model_service.h"

#include "server/call_scope.h"
#include "server/convert.h"
#include "server/implemented_rpcs.h"
#include "server/status_mapping.h"
#include "server/version.h"

namespace animspace::server {

grpc::Status ModelServiceImpl::ListModels(grpc::ServerContext*, const v1::ListModelsRequest*,
                                          v1::ListModelsResponse* response) {
  CallScope scope(env_.metrics, "ModelService/ListModels");
  for (const auto& entry : env_.registry.list()) to_proto(entry, response->add_models());
  return scope.finish(grpc::Status::OK);
}

grpc::Status ModelServiceImpl::DescribeModel(grpc::ServerContext*, const v1::DescribeModelRequest* request,
                                             v1::DescribeModelResponse* response) {
  CallScope scope(env_.metrics, "ModelService/DescribeModel");
  const auto& ref = request->model();
  scope.set_model(ref.name());
  if (auto valid = validate_model_name(ref.name()); !valid) return scope.finish(to_grpc_status(valid.error()));
  auto entry = env_.registry.describe(ref.name());
  if (!entry) return scope.finish(to_grpc_status(entry.error()));
  if (ref.version() != 0) {
    // Describe one version: keep only that one, after checking it exists.
    auto it = entry->versions.find(ref.version());
    if (it == entry->versions.end()) {
      return scope.finish(not_found("model.version: model '" + ref.name() + "' has no version " +
                                    std::to_string(ref.version())));
    }
    ModelEntry one{entry->name, {{it->first, it->second}}};
    to_proto(one, response->mutable_model());
    response->mutable_model()->set_default_version(entry->default_version());
    return scope.finish(grpc::Status::OK);
  }
  to_proto(*entry, response->mutable_model());
  return scope.finish(grpc::Status::OK);
}

grpc::Status ModelServiceImpl::LoadModel(grpc::ServerContext*, const v1::LoadModelRequest* request,
                                         v1::LoadModelResponse* response) {
  CallScope scope(env_.metrics, "ModelService/LoadModel");
  const auto& ref = request->model();
  scope.set_model(ref.name());
  if (auto valid = validate_model_name(ref.name()); !valid) return scope.finish(to_grpc_status(valid.error()));
  auto entry = env_.registry.load(ref.name(), ref.version());
  env_.metrics.set_models_loaded(env_.registry.loaded_version_count());
  if (!entry) return scope.finish(to_grpc_status(entry.error()));
  to_proto(*entry, response->mutable_model());
  return scope.finish(grpc::Status::OK);
}

grpc::Status ModelServiceImpl::UnloadModel(grpc::ServerContext*, const v1::UnloadModelRequest* request,
                                           v1::UnloadModelResponse*) {
  CallScope scope(env_.metrics, "ModelService/UnloadModel");
  const auto& ref = request->model();
  scope.set_model(ref.name());
  if (auto valid = validate_model_name(ref.name()); !valid) return scope.finish(to_grpc_status(valid.error()));
  auto status = env_.registry.unload(ref.name(), ref.version());
  env_.metrics.set_models_loaded(env_.registry.loaded_version_count());
  if (!status) return scope.finish(to_grpc_status(status.error()));
  return scope.finish(grpc::Status::OK);
}

grpc::Status ModelServiceImpl::GetServerInfo(grpc::ServerContext*, const v1::GetServerInfoRequest*,
                                             v1::GetServerInfoResponse* response) {
  CallScope scope(env_.metrics, "ModelService/GetServerInfo");
  response->set_server_version(kServerVersion);
  response->set_api("animspace.v1");
  response->set_started_at_unix_s(
      std::chrono::duration_cast<std::chrono::seconds>(env_.started_at.time_since_epoch()).count());
  response->set_max_message_bytes(static_cast<uint64_t>(env_.options.max_message_bytes));
  response->set_max_batch_poses(env_.options.max_batch_poses);
  response->set_max_thumbnail_px(env_.options.max_thumbnail_px);
  response->set_max_concurrent_calls(env_.options.max_concurrent_calls);
  response->set_renderer("none");
  for (const char* rpc : kImplementedRpcs) response->add_implemented_rpcs(rpc);
  return scope.finish(grpc::Status::OK);
}

}  // namespace animspace::server
