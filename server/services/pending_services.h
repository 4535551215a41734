// Services whose issues have not landed yet. Every method answers UNIMPLEMENTED with a message
// naming what is missing — never fake data — and is counted in the metrics like any call.
// Each class moves to its own file when its issue implements it.
#pragma once

#include "animspace/v1/lod.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "animspace/v1/skinning.grpc.pb.h"
#include "animspace/v1/training.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class PoseServiceImpl final : public v1::PoseService::Service {
 public:
  explicit PoseServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::Status DescribeKeyPoints(grpc::ServerContext*, const v1::DescribeKeyPointsRequest*,
                                 v1::DescribeKeyPointsResponse*) override;
  grpc::Status EvaluateKeyPoints(grpc::ServerContext*, const v1::EvaluateKeyPointsRequest*,
                                 v1::EvaluateKeyPointsResponse*) override;
  grpc::Status StreamKeyPoints(grpc::ServerContext*,
                               grpc::ServerReaderWriter<v1::PoseResult, v1::KeyPointFrame>*) override;
  grpc::Status CompleteMiss(grpc::ServerContext*, const v1::CompleteMissRequest*,
                            v1::CompleteMissResponse*) override;

 private:
  ServiceEnvironment& env_;
};

class SkinningServiceImpl final : public v1::SkinningService::Service {
 public:
  explicit SkinningServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::Status EvaluateSkeletonPose(grpc::ServerContext*, const v1::EvaluateSkeletonPoseRequest*,
                                    v1::EvaluateSkeletonPoseResponse*) override;

 private:
  ServiceEnvironment& env_;
};

class LodServiceImpl final : public v1::LodService::Service {
 public:
  explicit LodServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::Status GetLod(grpc::ServerContext*, const v1::GetLodRequest*,
                      grpc::ServerWriter<v1::LodChunk>*) override;

 private:
  ServiceEnvironment& env_;
};

class RenderServiceImpl final : public v1::RenderService::Service {
 public:
  explicit RenderServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::Status RenderThumbnail(grpc::ServerContext*, const v1::RenderThumbnailRequest*,
                               v1::RenderThumbnailResponse*) override;

 private:
  ServiceEnvironment& env_;
};

class TrainingServiceImpl final : public v1::TrainingService::Service {
 public:
  explicit TrainingServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::Status Retrain(grpc::ServerContext*, const v1::RetrainRequest*, v1::RetrainResponse*) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
