#include "server/services/training_service.h"

#include <spdlog/spdlog.h>

#include "core/misslog/miss_log.h"
#include "core/pmsc/retrain.h"
#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"

namespace animspace::server {
namespace {

// The full frames of the logged misses after `after_sequence` (records without full values are
// skipped: nothing to learn from). `last_sequence` receives the newest record read.
grpc::Status read_miss_frames(const std::filesystem::path& path, uint64_t after_sequence, long width,
                              FrameMatrix& frames, uint64_t& last_sequence) {
  last_sequence = after_sequence;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    frames.resize(0, width);
    return grpc::Status::OK;
  }
  misslog::ReadReport report;
  auto records = misslog::read_records(path, after_sequence, &report);
  if (!records) return to_grpc_status(records.error());
  long usable = 0;
  for (const auto& record : *records) usable += static_cast<long>(record.full_values.size()) == width ? 1 : 0;
  frames.resize(usable, width);
  long row = 0;
  for (const auto& record : *records) {
    last_sequence = std::max(last_sequence, record.sequence);
    if (static_cast<long>(record.full_values.size()) != width) continue;
    frames.row(row++) = Eigen::Map<const Eigen::RowVectorXf>(record.full_values.data(), width);
  }
  return grpc::Status::OK;
}

}  // namespace

grpc::ServerUnaryReactor* TrainingServiceImpl::Retrain(grpc::CallbackServerContext* context,
                                                       const v1::RetrainRequest* request,
                                                       v1::RetrainResponse* response) {
  return serve_unary(
      env_, context, "TrainingService/Retrain", Access::kAdmin, env_.admin_pool,
      [this, request, response](const CallControl& call) {
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) return s;
        if (grpc::Status s = require_pmsc(*model, "only PMSC subspaces are retrained from logged misses"); !s.ok()) {
          return s;
        }
        if (request->error_bound() < 0 || !std::isfinite(request->error_bound())) {
          return invalid_argument("error_bound: expected a finite value ≥ 0 (0 keeps the model's), got " +
                                  std::to_string(request->error_bound()));
        }
        {
          std::lock_guard lock(mutex_);
          if (!retraining_.insert(model->name).second) {
            return grpc::Status{grpc::StatusCode::ABORTED,
                                "a retrain of model '" + model->name + "' is already running; try again when it ends"};
          }
        }
        struct Release {
          TrainingServiceImpl* self;
          std::string name;
          ~Release() {
            std::lock_guard lock(self->mutex_);
            self->retraining_.erase(name);
          }
        } release{this, model->name};

        const long width = static_cast<long>(model->pmsc->point_count) * model->pmsc->channels;
        FrameMatrix misses(0, width);
        uint64_t last_sequence = pmsc::misses_through(model->container);
        if (!request->exclude_misses()) {
          if (grpc::Status s = read_miss_frames(env_.miss_logs.path_of(model->name),
                                                pmsc::misses_through(model->container), width, misses, last_sequence);
              !s.ok()) {
            return s;
          }
        }
        if (grpc::Status stop = call.stop_status(); !stop.ok()) return stop;

        pmsc::RetrainOptions options;
        options.error_bound = request->error_bound();
        options.max_key_points = static_cast<int>(request->max_key_points());
        auto result = pmsc::retrain(model->container, model->version, misses, last_sequence, options,
                                    model->path.string());
        if (!result) return to_grpc_status(result.error());
        response->set_training_frames(static_cast<uint32_t>(result->training_frames));
        response->set_misses_used(static_cast<uint32_t>(result->misses_used));
        response->set_basis_size(static_cast<uint32_t>(result->report.basis_size));
        response->set_key_point_count(static_cast<uint32_t>(result->report.key_points));
        response->set_max_training_error(static_cast<float>(result->report.max_training_error));
        response->set_condition_number(result->report.condition_number);
        response->set_training_seconds(result->report.seconds);
        if (request->dry_run()) return grpc::Status::OK;
        // Past this point the work is kept even if the client has gone: a published version is
        // the point of the call, and cancelling half-way would only waste the training.
        auto version = env_.registry.publish(model->name, result->container);
        if (!version) return to_grpc_status(version.error());
        refresh_model_gauges(env_);
        response->set_new_version(*version);
        spdlog::info("model {} retrained from version {}: version {} ({} frames, {} misses, M = {}, K = {}, {:.2f} s)",
                     model->name, model->version, *version, result->training_frames, result->misses_used,
                     result->report.basis_size, result->report.key_points, result->report.seconds);
        return grpc::Status::OK;
      });
}

}  // namespace animspace::server
