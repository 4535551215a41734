// animspace.v1.StatsService: per-model soft-cache and latency statistics.
#pragma once

#include "animspace/v1/stats.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class StatsServiceImpl final : public v1::StatsService::CallbackService {
 public:
  explicit StatsServiceImpl(ServiceEnvironment& env) : env_(env) {}
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context, const v1::GetStatsRequest* request,
                                     v1::GetStatsResponse* response) override;

 private:
  ServiceEnvironment& env_;
};

}  // namespace animspace::server
