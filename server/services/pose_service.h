// animspace.v1.PoseService: key points in, whole poses out through the PMSC soft cache.
#pragma once

#include "animspace/v1/poses.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class PoseServiceImpl final : public v1::PoseService::CallbackService {
 public:
  explicit PoseServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* DescribeKeyPoints(grpc::CallbackServerContext* context,
                                              const v1::DescribeKeyPointsRequest* request,
                                              v1::DescribeKeyPointsResponse* response) override;
  grpc::ServerUnaryReactor* EvaluateKeyPoints(grpc::CallbackServerContext* context,
                                              const v1::EvaluateKeyPointsRequest* request,
                                              v1::EvaluateKeyPointsResponse* response) override;
  grpc::ServerBidiReactor<v1::KeyPointFrame, v1::PoseResult>* StreamKeyPoints(
      grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* CompleteMiss(grpc::CallbackServerContext* context,
                                         const v1::CompleteMissRequest* request,
                                         v1::CompleteMissResponse* response) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
