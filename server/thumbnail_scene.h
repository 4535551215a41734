// What a RenderThumbnail request draws of its model: the source (PMSC key points through the soft
// cache, a skeleton pose, a stored sequence frame, or the rest pose; an illumination model's lit
// surface) posed into the scene with its overlays (wireframe, key points, heat map). The geometry
// and colours are core's (core/thumbnail/); this file decodes the request, evaluates a pose as
// every other pose is evaluated (server/pose_evaluation.h: counted and logged), and chooses.
#pragma once

#include <grpcpp/support/status.h>

#include "animspace/v1/render.pb.h"
#include "core/render/scene.h"
#include "server/model_registry.h"
#include "server/service_environment.h"

namespace animspace::server {

// Fills `scene`'s geometry and overlays from `request` for `model`; `scene` already holds the
// view (read_thumbnail_view). Sets the response's pose (for key_points: the verdict, without the
// points), heat_max_error and heat_scale_max (for a heat map) and lod_level (the level drawn).
// Every check that can refuse runs before the pose is evaluated, so a refused request leaves no
// trace in the statistics or the miss log. Refusals: INVALID_ARGUMENT naming the field;
// FAILED_PRECONDITION (unsupported_by_kind) for a source or overlay the model's kind cannot give,
// and for texture_checker on a model that stores no texture atlas; a core error through
// to_grpc_status.
grpc::Status build_thumbnail_scene(ServiceEnvironment& env, const LoadedModel& model,
                                   const v1::RenderThumbnailRequest& request, render::Scene& scene,
                                   v1::RenderThumbnailResponse* response);

}  // namespace animspace::server
