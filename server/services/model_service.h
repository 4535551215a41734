// animspace.v1.ModelService: list, describe, load, unload, server info.
#pragma once

#include "animspace/v1/models.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
using RawModelService =
    v1::ModelService::WithRawCallbackMethod_ListModels<v1::ModelService::WithRawCallbackMethod_DescribeModel<
        v1::ModelService::WithRawCallbackMethod_LoadModel<v1::ModelService::WithRawCallbackMethod_UnloadModel<
            v1::ModelService::WithRawCallbackMethod_GetServerInfo<v1::ModelService::Service>>>>>;

class ModelServiceImpl final : public RawModelService {
 public:
  explicit ModelServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* ListModels(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                       grpc::ByteBuffer* response_bytes) override;
  grpc::ServerUnaryReactor* DescribeModel(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                          grpc::ByteBuffer* response_bytes) override;
  grpc::ServerUnaryReactor* LoadModel(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                      grpc::ByteBuffer* response_bytes) override;
  grpc::ServerUnaryReactor* UnloadModel(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                        grpc::ByteBuffer* response_bytes) override;
  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                          grpc::ByteBuffer* response_bytes) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
