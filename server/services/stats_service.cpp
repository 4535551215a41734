#include "server/services/stats_service.h"

#include "server/model_lookup.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"

namespace animspace::server {
namespace {

void to_proto(const Histogram& h, v1::Histogram* out) {
  for (double bound : h.upper_bounds()) out->add_upper_bounds(bound);
  for (uint64_t count : h.counts()) out->add_counts(count);
  out->set_total_count(h.total_count());
  out->set_sum(h.sum());
}

void to_proto(const std::string& name, const ModelStatistics& s, v1::ModelStats* out) {
  out->set_model(name);
  out->set_requests(s.requests);
  out->set_poses(s.poses);
  out->set_hits(s.hits);
  out->set_blends(s.blends);
  out->set_misses(s.misses);
  out->set_errors(s.errors);
  // Of the poses that had a verdict: skeleton poses never pass the soft cache.
  const uint64_t verdicts = s.hits + s.blends + s.misses;
  out->set_hit_rate(verdicts == 0 ? 0.0 : static_cast<double>(s.hits) / static_cast<double>(verdicts));
  to_proto(s.key_point_error, out->mutable_key_point_error());
  to_proto(s.latency_seconds, out->mutable_latency_seconds());
  out->set_latency_p50_s(s.latency_seconds.quantile(0.50));
  out->set_latency_p90_s(s.latency_seconds.quantile(0.90));
  out->set_latency_p99_s(s.latency_seconds.quantile(0.99));
}

}  // namespace

grpc::ServerUnaryReactor* StatsServiceImpl::GetStats(grpc::CallbackServerContext* context,
                                                     const grpc::ByteBuffer* request_bytes,
                                                     grpc::ByteBuffer* response_bytes) {
  // Reading is for everyone; zeroing the counters is an operator's decision.
  const auto access = [](const v1::GetStatsRequest& r) { return r.reset() ? Access::kAdmin : Access::kUser; };
  return serve_unary<v1::GetStatsRequest, v1::GetStatsResponse>(
      env_, {context, request_bytes, response_bytes}, "StatsService/GetStats", access, env_.request_pool,
      [this](const CallControl& call, const v1::GetStatsRequest* request, v1::GetStatsResponse* response) {
        const std::string& name = request->model();
        // Statistics exist for every model that is loaded, including ones never called yet.
        std::map<std::string, ModelStatistics> stats = env_.metrics.model_statistics();
        for (const auto& entry : env_.registry.list()) stats.try_emplace(entry.name);
        if (!name.empty()) {
          if (auto valid = validate_model_name(name, "model"); !valid) return to_grpc_status(valid.error());
          auto it = stats.find(name);
          if (it == stats.end()) return unknown_model(env_.registry, name);
          call.set_model(name);
          to_proto(it->first, it->second, response->add_models());
        } else {
          for (const auto& [model, s] : stats) to_proto(model, s, response->add_models());
        }
        response->set_since_unix_s(std::chrono::duration_cast<std::chrono::seconds>(
                                       env_.metrics.statistics_since().time_since_epoch())
                                       .count());
        if (request->reset()) env_.metrics.reset_model_statistics(name);
        return grpc::Status::OK;
      });
}

}  // namespace animspace::server
