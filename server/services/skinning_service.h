// animspace.v1.SkinningService: skeleton poses through an animation-space model (Merry 2007 §3.1,
// normals §3.5), at full detail or at one of its LOD levels (§7.3).
#pragma once

#include "animspace/v1/skinning.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class SkinningServiceImpl final : public v1::SkinningService::CallbackService {
 public:
  explicit SkinningServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* EvaluateSkeletonPose(grpc::CallbackServerContext* context,
                                                 const v1::EvaluateSkeletonPoseRequest* request,
                                                 v1::EvaluateSkeletonPoseResponse* response) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
