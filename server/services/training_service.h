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

// Every method raw: requests arrive as bytes (server/raw_messages.h).
class TrainingServiceImpl final
    : public v1::TrainingService::WithRawCallbackMethod_Retrain<v1::TrainingService::Service> {
 public:
  explicit TrainingServiceImpl(ServiceEnvironment& env) : env_(env) {}

  grpc::ServerUnaryReactor* Retrain(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                    grpc::ByteBuffer* response_bytes) override;

 private:
  ServiceEnvironment& env_;
  std::mutex mutex_;
  std::set<std::string> retraining_;  // models with a retrain running
};

}  // namespace animspace::server
