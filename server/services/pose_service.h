// animspace.v1.PoseService: key points in, whole poses out through the PMSC soft cache.
#pragma once

#include "animspace/v1/poses.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
using RawPoseService = v1::PoseService::WithRawCallbackMethod_DescribeKeyPoints<
    v1::PoseService::WithRawCallbackMethod_EvaluateKeyPoints<v1::PoseService::WithRawCallbackMethod_StreamKeyPoints<
        v1::PoseService::WithRawCallbackMethod_CompleteMiss<
            v1::PoseService::WithRawCallbackMethod_GetBasis<v1::PoseService::Service>>>>>;

class PoseServiceImpl final : public RawPoseService {
 public:
  explicit PoseServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* DescribeKeyPoints(grpc::CallbackServerContext* context,
                                              const grpc::ByteBuffer* request_bytes,
                                              grpc::ByteBuffer* response_bytes) override;
  grpc::ServerUnaryReactor* EvaluateKeyPoints(grpc::CallbackServerContext* context,
                                              const grpc::ByteBuffer* request_bytes,
                                              grpc::ByteBuffer* response_bytes) override;
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* StreamKeyPoints(
      grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* CompleteMiss(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                         grpc::ByteBuffer* response_bytes) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* GetBasis(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request_bytes) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
