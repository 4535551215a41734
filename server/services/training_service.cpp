#include "server/services/training_service.h"

#include <spdlog/spdlog.h>

#include "core/misslog/miss_frames.h"
#include "core/pmsc/retrain.h"
#include "server/model_lookup.h"
#include "server/pose_input.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"

namespace animspace::server {
grpc::ServerUnaryReactor* TrainingServiceImpl::Retrain(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request_bytes,
                                                       grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::RetrainRequest, v1::RetrainResponse>(
      env_, {context, request_bytes, response_bytes}, "TrainingService/Retrain", Access::kAdmin, env_.admin_pool,
      [this](const CallControl& call, const v1::RetrainRequest* request, v1::RetrainResponse* response) {
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

        const long width = static_cast<long>(model->pmsc->point_count) * model->pmsc->channel_count;
        FrameMatrix misses(0, width);
        uint64_t last_sequence = pmsc::misses_through(model->container);
        uint64_t without_full_values = 0;
        if (!request->exclude_misses()) {
          auto read = misslog::read_miss_frames(env_.miss_logs.path_of(model->name), last_sequence, *model->pmsc,
                                                model->version);
          if (!read) return to_grpc_status(read.error());
          misses = std::move(read->frames);
          last_sequence = read->last_sequence;
          without_full_values = read->skipped;
          response->set_misses_inconsistent(static_cast<uint32_t>(read->inconsistent));
          if (read->inconsistent > 0) {
            spdlog::warn("model {}: {} logged miss(es) left out of the retrain: their full values do not repeat "
                         "their key values", model->name, read->inconsistent);
          }
        }
        if (grpc::Status stop = call.stop_status(); !stop.ok()) return stop;

        pmsc::RetrainOptions options;
        options.error_bound = request->error_bound();
        options.max_key_points = static_cast<int>(request->max_key_points());
        auto changes = pmsc::retrain_changes_anything(model->container, misses.rows(), options, model->path.string());
        if (!changes) return to_grpc_status(changes.error());
        response->set_unchanged(!*changes);
        if (!*changes && !request->dry_run()) {
          return failed_precondition(
              "model '" + model->name + "' version " + std::to_string(model->version) +
              ": nothing new to train on — " +
              (request->exclude_misses()
                   ? std::string("misses excluded")
                   : "no logged miss with full values since its training (" + std::to_string(without_full_values) +
                         " logged without them: a client completes a miss with CompleteMiss, e.g. `animspace play "
                         "--complete`)") +
              " and no option changed, so a retrain would publish a copy of this version; nothing was published");
        }
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
        response->set_previous_epsilon_min(static_cast<float>(result->previous_epsilon.epsilon_min));
        response->set_previous_epsilon_max(static_cast<float>(result->previous_epsilon.epsilon_max));
        response->set_epsilon_min(static_cast<float>(result->epsilon.epsilon_min));
        response->set_epsilon_max(static_cast<float>(result->epsilon.epsilon_max));
        response->set_previous_hit_rate(result->previous_hit_rate);
        response->set_hit_rate(result->hit_rate);
        if (request->dry_run()) return grpc::Status::OK;
        // Past this point the work is kept even if the client has gone: a published version is
        // the point of the call, and cancelling half-way would only waste the training.
        auto version = env_.registry.publish(model->name, result->container);
        if (!version) return to_grpc_status(version.error());
        refresh_model_gauges(env_);
        response->set_new_version(*version);
        spdlog::info("model {} retrained from version {}: version {} ({} frames, {} misses, M = {}, K = {}, {:.2f} s); "
                     "ε_min {:.4g} → {:.4g}, ε_max {:.4g} → {:.4g}; hit rate on the training frames {:.1f}% → {:.1f}%",
                     model->name, model->version, *version, result->training_frames, result->misses_used,
                     result->report.basis_size, result->report.key_points, result->report.seconds,
                     result->previous_epsilon.epsilon_min, result->epsilon.epsilon_min,
                     result->previous_epsilon.epsilon_max, result->epsilon.epsilon_max,
                     100 * result->previous_hit_rate, 100 * result->hit_rate);
        return grpc::Status::OK;
      });
}

}  // namespace animspace::server
