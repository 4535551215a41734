// What a RenderThumbnail request asks of the picture itself, before any model is looked at: size,
// multisampling, background, shading, screen tolerance and camera, checked and written into the
// scene (core/render/scene.h). A refusal names the field with the expected and the actual value.
#pragma once

#include <grpcpp/support/status.h>

#include "animspace/v1/render.pb.h"
#include "core/render/scene.h"
#include "server/options.h"

namespace animspace::server {

// OK with scene.width, height, samples, background, shading and (when the request has one) camera
// set; INVALID_ARGUMENT otherwise: a size outside 1..options.max_thumbnail_px, samples not
// 0/1/2/4/8 (0 = 4), a background of other than 4 values or outside [0, 1], an unknown shading,
// a negative or non-finite tolerance_px / pixel_tolerance or the two disagreeing, a camera whose
// vectors are not 3 values or that render::validate_camera refuses.
grpc::Status read_thumbnail_view(const v1::RenderThumbnailRequest& request, const ServerOptions& options,
                                 render::Scene& scene);

// tolerance_px, or the deprecated pixel_tolerance an older client sends (read_thumbnail_view
// checked that they agree when both are set). Pixels, ≥ 0; 0 = full detail.
float thumbnail_tolerance_px(const v1::RenderThumbnailRequest& request);

}  // namespace animspace::server
