// RenderService: thumbnails of a posed model drawn headless through EGL on the render thread.
#pragma once

#include "animspace/v1/render.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

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
