#include "server/services/pending_services.h"

#include "server/call_scope.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

grpc::Status pending(Metrics& metrics, const char* rpc, const std::string& model, const char* why) {
  CallScope scope(metrics, rpc);
  scope.set_model(model);
  return scope.finish(unimplemented(std::string("animspace.v1.") + rpc, why));
}

constexpr const char* kPmscPending =
    "the PMSC soft cache (issues #3 and #6) has not landed; no subspace can be evaluated yet";
constexpr const char* kSkinningPending =
    "animation-space evaluation (issues #4 and #6) has not landed";
constexpr const char* kLodPending = "animation-space level of detail (issues #5 and #7) has not landed";
constexpr const char* kRenderPending = "headless EGL thumbnails (issue #7) have not landed";
constexpr const char* kTrainingPending = "retraining from logged misses (issue #6) has not landed";

}  // namespace

grpc::Status PoseServiceImpl::DescribeKeyPoints(grpc::ServerContext*, const v1::DescribeKeyPointsRequest* request,
                                                v1::DescribeKeyPointsResponse*) {
  return pending(env_.metrics, "PoseService/DescribeKeyPoints", request->model().name(), kPmscPending);
}

grpc::Status PoseServiceImpl::EvaluateKeyPoints(grpc::ServerContext*, const v1::EvaluateKeyPointsRequest* request,
                                                v1::EvaluateKeyPointsResponse*) {
  return pending(env_.metrics, "PoseService/EvaluateKeyPoints", request->model().name(), kPmscPending);
}

grpc::Status PoseServiceImpl::StreamKeyPoints(grpc::ServerContext*,
                                              grpc::ServerReaderWriter<v1::PoseResult, v1::KeyPointFrame>*) {
  return pending(env_.metrics, "PoseService/StreamKeyPoints", "", kPmscPending);
}

grpc::Status PoseServiceImpl::CompleteMiss(grpc::ServerContext*, const v1::CompleteMissRequest* request,
                                           v1::CompleteMissResponse*) {
  return pending(env_.metrics, "PoseService/CompleteMiss", request->model().name(), kPmscPending);
}

grpc::Status SkinningServiceImpl::EvaluateSkeletonPose(grpc::ServerContext*,
                                                       const v1::EvaluateSkeletonPoseRequest* request,
                                                       v1::EvaluateSkeletonPoseResponse*) {
  return pending(env_.metrics, "SkinningService/EvaluateSkeletonPose", request->model().name(), kSkinningPending);
}

grpc::Status LodServiceImpl::GetLod(grpc::ServerContext*, const v1::GetLodRequest* request,
                                    grpc::ServerWriter<v1::LodChunk>*) {
  return pending(env_.metrics, "LodService/GetLod", request->model().name(), kLodPending);
}

grpc::Status RenderServiceImpl::RenderThumbnail(grpc::ServerContext*, const v1::RenderThumbnailRequest* request,
                                                v1::RenderThumbnailResponse*) {
  return pending(env_.metrics, "RenderService/RenderThumbnail", request->model().name(), kRenderPending);
}

grpc::Status TrainingServiceImpl::Retrain(grpc::ServerContext*, const v1::RetrainRequest* request,
                                          v1::RetrainResponse*) {
  return pending(env_.metrics, "TrainingService/Retrain", request->model().name(), kTrainingPending);
}

}  // namespace animspace::server
