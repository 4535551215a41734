#include "server/services/model_service.h"

#include "core/common/kernels.h"
#include "server/convert.h"
#include "server/implemented_rpcs.h"
#include "server/model_lookup.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"
#include "server/validation.h"
#include "server/version.h"

namespace animspace::server {

grpc::ServerUnaryReactor* ModelServiceImpl::ListModels(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request_bytes,
                                                       grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::ListModelsRequest, v1::ListModelsResponse>(
      env_, {context, request_bytes, response_bytes}, "ModelService/ListModels", Access::kUser, env_.request_pool,
      [this](const CallControl&, const v1::ListModelsRequest*, v1::ListModelsResponse* response) {
        for (const auto& entry : env_.registry.list()) to_proto(entry, response->add_models());
        return grpc::Status::OK;
      });
}

grpc::ServerUnaryReactor* ModelServiceImpl::DescribeModel(grpc::CallbackServerContext* context,
                                                          const grpc::ByteBuffer* request_bytes,
                                                          grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::DescribeModelRequest, v1::DescribeModelResponse>(
      env_, {context, request_bytes, response_bytes}, "ModelService/DescribeModel", Access::kUser, env_.request_pool,
      [this](const CallControl& call, const v1::DescribeModelRequest* request, v1::DescribeModelResponse* response) {
        const auto& ref = request->model();
        if (grpc::Status s = check_model_ref(ref, "model"); !s.ok()) return s;
        auto entry = env_.registry.describe(ref.name());
        if (!entry) return entry.error().code == ErrorCode::kNotFound ? unknown_model(env_.registry, ref.name())
                                                                     : to_grpc_status(entry.error());
        call.set_model(ref.name());
        if (ref.version() == 0) {
          to_proto(*entry, response->mutable_model());
          return grpc::Status::OK;
        }
        // Describe one version: keep only that one, after checking it exists.
        auto it = entry->versions.find(ref.version());
        if (it == entry->versions.end()) {
          return not_found("model.version: model '" + ref.name() + "' has no version " +
                           std::to_string(ref.version()));
        }
        ModelEntry one{entry->name, {{it->first, it->second}}};
        to_proto(one, response->mutable_model());
        response->mutable_model()->set_default_version(entry->default_version());
        return grpc::Status::OK;
      });
}

grpc::ServerUnaryReactor* ModelServiceImpl::LoadModel(grpc::CallbackServerContext* context,
                                                      const grpc::ByteBuffer* request_bytes,
                                                      grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::LoadModelRequest, v1::LoadModelResponse>(
      env_, {context, request_bytes, response_bytes}, "ModelService/LoadModel", Access::kAdmin, env_.admin_pool,
      [this](const CallControl& call, const v1::LoadModelRequest* request, v1::LoadModelResponse* response) {
        const auto& ref = request->model();
        if (grpc::Status s = check_model_ref(ref, "model"); !s.ok()) return s;
        auto entry = env_.registry.load(ref.name(), ref.version());
        refresh_model_gauges(env_);
        if (!entry) return to_grpc_status(entry.error());
        call.set_model(ref.name());
        to_proto(*entry, response->mutable_model());
        return grpc::Status::OK;
      });
}

grpc::ServerUnaryReactor* ModelServiceImpl::UnloadModel(grpc::CallbackServerContext* context,
                                                        const grpc::ByteBuffer* request_bytes,
                                                        grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::UnloadModelRequest, v1::UnloadModelResponse>(
      env_, {context, request_bytes, response_bytes}, "ModelService/UnloadModel", Access::kAdmin, env_.admin_pool,
      [this](const CallControl& call, const v1::UnloadModelRequest* request, v1::UnloadModelResponse*) {
        const auto& ref = request->model();
        if (grpc::Status s = check_model_ref(ref, "model"); !s.ok()) return s;
        const bool known = env_.registry.describe(ref.name()).ok();
        auto status = env_.registry.unload(ref.name(), ref.version());
        refresh_model_gauges(env_);
        if (!status) return known ? to_grpc_status(status.error()) : unknown_model(env_.registry, ref.name());
        call.set_model(ref.name());
        return grpc::Status::OK;
      });
}

grpc::ServerUnaryReactor* ModelServiceImpl::GetServerInfo(grpc::CallbackServerContext* context,
                                                          const grpc::ByteBuffer* request_bytes,
                                                          grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::GetServerInfoRequest, v1::GetServerInfoResponse>(
      env_, {context, request_bytes, response_bytes}, "ModelService/GetServerInfo", Access::kUser, env_.request_pool,
      [this](const CallControl&, const v1::GetServerInfoRequest*, v1::GetServerInfoResponse* response) {
        response->set_server_version(kServerVersion);
        response->set_api("animspace.v1");
        response->set_started_at_unix_s(
            std::chrono::duration_cast<std::chrono::seconds>(env_.started_at.time_since_epoch()).count());
        response->set_max_message_bytes(static_cast<uint64_t>(env_.options.max_message_bytes));
        response->set_grpc_memory_bytes(static_cast<uint64_t>(env_.options.grpc_memory_bytes));
        response->set_max_batch_poses(env_.options.max_batch_poses);
        response->set_max_thumbnail_px(env_.options.max_thumbnail_px);
        response->set_max_concurrent_calls(env_.options.max_concurrent_calls);
        response->set_kernel(kernel_name(active_kernel()));
        response->set_max_batch_size(env_.options.max_batch_size);
        response->set_batch_delay_us(static_cast<uint64_t>(env_.options.batch_delay.count()));
        response->set_renderer(env_.renderer != nullptr ? env_.renderer->description()
                                                        : "none (" + env_.renderer_unavailable + ")");
        for (const char* rpc : kImplementedRpcs) {
          // Without a renderer the RPC answers UNAVAILABLE: not one to plan on.
          if (env_.renderer == nullptr && std::string_view(rpc) == kRenderThumbnailRpc) continue;
          response->add_implemented_rpcs(rpc);
        }
        return grpc::Status::OK;
      });
}

}  // namespace animspace::server
