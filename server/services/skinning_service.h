// animspace.v1.SkinningService: skeleton poses through an animation-space model (Merry 2007 §3.1,
// normals §3.5), at full detail or at one of its LOD levels (§7.3).
#pragma once

#include "animspace/v1/skinning.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
class SkinningServiceImpl final
    : public v1::SkinningService::WithRawCallbackMethod_EvaluateSkeletonPose<v1::SkinningService::Service> {
 public:
  explicit SkinningServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* EvaluateSkeletonPose(grpc::CallbackServerContext* context,
                                                 const grpc::ByteBuffer* request_bytes,
                                                 grpc::ByteBuffer* response_bytes) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
