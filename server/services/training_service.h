// animspace.v1.TrainingService: "train each night, better tomorrow" — a new PMSC subspace from
// the model's training frames plus the logged misses that carry full values, published as the
// next version and hot-swapped in (server/model_registry.h, publish()).
#pragma once

#include <mutex>
#include <set>
#include <string>

#include "animspace/v1/training.grpc.pb.h"
#include "server/service_environment.h"

namespace animspace::server {

class TrainingServiceImpl final : public v1::TrainingService::CallbackService {
 public:
  explicit TrainingServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* Retrain(grpc::CallbackServerContext* context, const v1::RetrainRequest* request,
                                    v1::RetrainResponse* response) override;

 private:
  ServiceEnvironment& env_;
  std::mutex mutex_;
  std::set<std::string> retraining_;  // models with a retrain running
};

}  // namespace animspace::server
