// animspace.v1.StatsService: per-model soft-cache and latency statistics.
#pragma once

#include "animspace/v1/stats.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

// Every method raw: requests arrive as bytes (server/raw_messages.h).
class StatsServiceImpl final : public v1::StatsService::WithRawCallbackMethod_GetStats<v1::StatsService::Service> {
 public:
  explicit StatsServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                     grpc::ByteBuffer* response_bytes) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
