#include "server/services/skinning_service.h"

#include "core/animspace/model.h"
#include "server/lod_selection.h"
#include "server/model_lookup.h"
#include "server/unary_call.h"
#include "server/validation.h"

namespace animspace::server {

grpc::ServerUnaryReactor* SkinningServiceImpl::EvaluateSkeletonPose(grpc::CallbackServerContext* context,
                                                                    const grpc::ByteBuffer* request_bytes,
                                                                    grpc::ByteBuffer* response_bytes) {
  return serve_unary<v1::EvaluateSkeletonPoseRequest, v1::EvaluateSkeletonPoseResponse>(
      env_, {context, request_bytes, response_bytes}, "SkinningService/EvaluateSkeletonPose", Access::kUser,
      env_.request_pool,
      [this](const CallControl& call, const v1::EvaluateSkeletonPoseRequest* request,
             v1::EvaluateSkeletonPoseResponse* response) {
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) return s;
        if (grpc::Status s = require_skeleton(*model, "it cannot evaluate skeleton poses"); !s.ok()) return s;
        const lod::LodLevel* level = nullptr;
        if (grpc::Status s = find_lod_level(*model, request->lod_level(), "lod_level", &level); !s.ok()) return s;
        const animation_space::AnimationSpaceModel* skinned = &level->model;
        if (request->include_normals() && !skinned->has_tangents()) {
          return grpc::Status{grpc::StatusCode::FAILED_PRECONDITION,
                              "include_normals: model '" + model->name +
                                  "' stores no tangent planes (Merry 2007 §3.5), so it has no normals to pose"};
        }
        if (grpc::Status s = check_batch_size(request->poses_size(), env_.options.max_batch_poses, "poses"); !s.ok()) {
          return s;
        }
        const uint64_t bytes_per_pose = uint64_t{12} * static_cast<uint64_t>(skinned->vertex_count()) *
                                        (request->include_normals() ? 2 : 1);
        if (grpc::Status s = check_response_size(request->poses_size(), bytes_per_pose, env_.options.max_message_bytes,
                                                 "poses");
            !s.ok()) {
          return s;
        }
        std::vector<animation_space::TransformList> poses(static_cast<size_t>(request->poses_size()));
        for (int i = 0; i < request->poses_size(); ++i) {
          if (grpc::Status s = decode_skeleton_pose(request->poses(i), "poses[" + std::to_string(i) + "]",
                                                    skinned->skeleton, poses[static_cast<size_t>(i)]);
              !s.ok()) {
            return s;
          }
        }
        response->set_model_version(model->version);
        const auto vertices = static_cast<uint32_t>(skinned->vertex_count());
        PointMatrix points;
        for (const auto& globals : poses) {
          if (grpc::Status stop = call.stop_status(); !stop.ok()) return stop;
          auto* out = response->add_poses();
          animation_space::evaluate(*skinned, globals, points);
          encode_points(points.data(), vertices, 3, out->mutable_points());
          if (request->include_normals()) {
            animation_space::evaluate_normals(*skinned, globals, points);
            encode_points(points.data(), vertices, 3, out->mutable_normals());
          }
        }
        env_.metrics.record_skeleton_poses(model->name, poses.size());
        return grpc::Status::OK;
      });
}

}  // namespace animspace::server
