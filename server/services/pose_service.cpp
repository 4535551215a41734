#include "server/services/pose_service.h"

#include "server/convert.h"
#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/services/basis_stream.h"
#include "server/services/key_point_stream.h"
#include "server/unary_call.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

// Most poses of one EvaluateKeyPoints call evaluated on the gRPC thread (evaluated_in_place): tens
// of microseconds; a larger batch goes to the request pool, where a long one cannot hold up the
// transport.
constexpr int kPosesEvaluatedInPlace = 16;

}  // namespace

grpc::ServerUnaryReactor* PoseServiceImpl::DescribeKeyPoints(grpc::CallbackServerContext* context,
                                                             const grpc::ByteBuffer* request_bytes,
                                                             grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::DescribeKeyPointsRequest, v1::DescribeKeyPointsResponse>(
      env_, {context, request_bytes, response_bytes}, "PoseService/DescribeKeyPoints", Access::kUser, env_.request_pool,
      [this](const CallControl& call, const v1::DescribeKeyPointsRequest* request,
             v1::DescribeKeyPointsResponse* response) {
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) {
          return s;
        }
        if (grpc::Status s = require_pmsc(*model); !s.ok()) return s;
        const pmsc::PmscModel& m = *model->pmsc;
        response->set_model_version(model->version);
        for (int k : m.key_points) response->add_key_point_indices(static_cast<uint32_t>(k));
        response->set_channel_count(static_cast<uint32_t>(m.channel_count));
        response->set_control_point_count(static_cast<uint32_t>(m.control_point_count));
        for (int r : m.key_regions) response->add_key_point_regions(static_cast<uint32_t>(r));
        response->set_fail_through(to_proto(model->info.fail_through));
        for (int c : m.check_points) response->add_check_point_indices(static_cast<uint32_t>(c));
        for (int r : m.check_regions) response->add_check_point_regions(static_cast<uint32_t>(r));
        response->set_basis_checksum(model->basis_checksum);
        response->set_basis_sha256(model->basis_sha256);
        return grpc::Status::OK;
      });
}

grpc::ServerUnaryReactor* PoseServiceImpl::EvaluateKeyPoints(grpc::CallbackServerContext* context,
                                                             const grpc::ByteBuffer* request_bytes,
                                                             grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::EvaluateKeyPointsRequest, v1::EvaluateKeyPointsResponse>(
      env_, {context, request_bytes, response_bytes}, "PoseService/EvaluateKeyPoints", Access::kUser, env_.request_pool,
      [this](const CallControl& call, const v1::EvaluateKeyPointsRequest* request,
             v1::EvaluateKeyPointsResponse* response) {
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) return s;
        if (grpc::Status s = require_pmsc(*model); !s.ok()) return s;
        if (grpc::Status s = check_batch_size(request->poses_size(), env_.options.max_batch_poses, "poses"); !s.ok()) {
          return s;
        }
        if (grpc::Status s = check_points_encoding(request->points_encoding(), "points_encoding"); !s.ok()) return s;
        const auto point_count = static_cast<uint64_t>(model->pmsc->point_count);
        const uint64_t bytes_per_point =
            bytes_per_value(request->points_encoding()) * static_cast<uint64_t>(model->pmsc->channel_count);
        // Local fail-through may name every point: a varint index (≤ 5 bytes) and a float each.
        const uint64_t bytes_per_pose =
            (request->omit_points() ? 0 : bytes_per_point * point_count) +
            (request->local_fail_through() ? uint64_t{9} * point_count : 0);
        if (grpc::Status s = check_response_size(request->poses_size(), bytes_per_pose, env_.options.max_message_bytes,
                                                 "poses");
            !s.ok()) {
          return s;
        }
        // Every pose is checked before any is evaluated: a bad batch logs no misses and counts no poses.
        std::vector<PoseJob> jobs(static_cast<size_t>(request->poses_size()));
        std::vector<v1::PoseResult*> results;
        results.reserve(jobs.size());
        for (int i = 0; i < request->poses_size(); ++i) {
          PoseJob& job = jobs[static_cast<size_t>(i)];
          if (grpc::Status s = decode_pose(*model, request->poses(i), "poses[" + std::to_string(i) + "]", job.input);
              !s.ok()) {
            return s;
          }
          job.options.include_region_errors = request->include_region_errors();
          job.options.omit_points = request->omit_points();
          job.options.points_encoding = request->points_encoding();
          job.options.local_fail_through = request->local_fail_through();
          job.options.log_misses = !request->skip_miss_log();
          results.push_back(response->add_results());
        }
        // The request's poses wait in the batcher together (with any other call's for this model):
        // their f̂ is one matrix product.
        PoseRun run;
        run.start(env_, *model, jobs, results);
        return run.finish(&call);
      },
      // A few poses answered as coordinates: evaluated where the call arrived.
      +[](const v1::EvaluateKeyPointsRequest& request) {
        if (request.poses_size() > kPosesEvaluatedInPlace) return false;
        for (const auto& pose : request.poses()) {
          if (!evaluated_in_place(request.points_encoding(), request.local_fail_through(), pose)) return false;
        }
        return true;
      });
}

grpc::ServerUnaryReactor* PoseServiceImpl::CompleteMiss(grpc::CallbackServerContext* context,
                                                        const grpc::ByteBuffer* request_bytes,
                                                        grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::CompleteMissRequest, v1::CompleteMissResponse>(
      env_, {context, request_bytes, response_bytes}, "PoseService/CompleteMiss", Access::kUser, env_.request_pool,
      [this](const CallControl& call, const v1::CompleteMissRequest* request, v1::CompleteMissResponse* response) {
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) return s;
        if (grpc::Status s = require_pmsc(*model); !s.ok()) return s;
        const pmsc::PmscModel& m = *model->pmsc;
        if (m.cross) {
          return grpc::Status{grpc::StatusCode::FAILED_PRECONDITION,
                              "model '" + model->name +
                                  "' is cross-PMSC: its key points drive a different point set, so no full "
                                  "values exist to complete a miss with (fail-through impossible)"};
        }
        if (grpc::Status s = check_points_encoding(request->points_encoding(), "points_encoding"); !s.ok()) {
          return s;
        }
        PoseInput input;
        if (grpc::Status s = decode_points(request->key_values(), "key_values",
                                           static_cast<uint32_t>(m.key_point_count()),
                                           static_cast<uint32_t>(m.channel_count), "key points", input.key_values);
            !s.ok()) {
          return s;
        }
        // The check values the evaluation sent, so that the verdict (and so α) repeats.
        if (grpc::Status s = decode_check_values(*model, request->has_check_values(), request->check_values(),
                                                 "check_values", input.check_values);
            !s.ok()) {
          return s;
        }
        if (grpc::Status s = decode_point_indices(request->full_points(), "full_points",
                                                  static_cast<uint32_t>(m.point_count), input.full_points);
            !s.ok()) {
          return s;
        }
        // Nothing inconsistent reaches the miss log: it is tomorrow's training data.
        if (grpc::Status s = decode_full_values(*model, request->full_values(), "full_values", input.key_values,
                                                input.check_values, input.full_points, input.full_values);
            !s.ok()) {
          return s;
        }
        PoseOptions options;
        options.count_in_statistics = false;
        options.points_encoding = request->points_encoding();
        options.log_misses = !request->skip_miss_log();
        bool logged = false;
        if (grpc::Status s = evaluate_pose(env_, *model, input, options, response->mutable_result(), &logged,
                                           response->mutable_not_logged_reason());
            !s.ok()) {
          return s;
        }
        response->set_logged(logged);
        return grpc::Status::OK;
      });
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* PoseServiceImpl::GetBasis(grpc::CallbackServerContext* context,
                                                                      const grpc::ByteBuffer* request_bytes) {
  return start_basis_stream(env_, context, request_bytes);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* PoseServiceImpl::StreamKeyPoints(
    grpc::CallbackServerContext* context) {
  return KeyPointStream::start(env_, context);
}

}  // namespace animspace::server
