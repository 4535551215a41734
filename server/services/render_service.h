// RenderService: thumbnails of a posed model drawn headless through EGL on the render thread.
// The request's view is read by server/thumbnail_view.h, the scene built by
// server/thumbnail_scene.h (core/thumbnail/ below it); the service submits the draw and answers.
#pragma once

#include "animspace/v1/render.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
class RenderServiceImpl final
    : public v1::RenderService::WithRawCallbackMethod_RenderThumbnail<v1::RenderService::Service> {
 public:
  explicit RenderServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerUnaryReactor* RenderThumbnail(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                            grpc::ByteBuffer* response_bytes) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
