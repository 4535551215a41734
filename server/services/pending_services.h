// Services whose issues have not landed yet. Every method answers UNIMPLEMENTED with a message
// naming what is missing — never fake data — and is counted in the metrics like any call.
// Each class moves to its own file when its issue implements it.
#pragma once

#include "animspace/v1/lod.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class LodServiceImpl final : public v1::LodService::CallbackService {
 public:
  explicit LodServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerWriteReactor<v1::LodChunk>* GetLod(grpc::CallbackServerContext* context,
                                                 const v1::GetLodRequest* request) override;

 private:
  ServiceEnvironment& env_;
};

class RenderServiceImpl final : public v1::RenderService::CallbackService {
 public:
  explicit RenderServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerUnaryReactor* RenderThumbnail(grpc::CallbackServerContext* context,
                                            const v1::RenderThumbnailRequest* request,
                                            v1::RenderThumbnailResponse* response) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
