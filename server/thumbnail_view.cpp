#include "server/thumbnail_view.h"

#include <cmath>
#include <string>
#include <tuple>
#include <utility>

#include "core/common/format.h"
#include "core/render/camera.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

using Request = v1::RenderThumbnailRequest;

constexpr int kDefaultSamples = 4;

}  // namespace

grpc::Status read_thumbnail_view(const Request& request, const ServerOptions& options, render::Scene& scene) {
  const uint32_t max_px = options.max_thumbnail_px;
  for (const auto& [field, value] : {std::pair{"width_px", request.width_px()}, {"height_px", request.height_px()}}) {
    if (value < 1 || value > max_px) {
      return invalid_argument(std::string(field) + ": expected 1.." + std::to_string(max_px) +
                              " pixels (--max-thumbnail-px), got " + std::to_string(value));
    }
  }
  scene.width = static_cast<int>(request.width_px());
  scene.height = static_cast<int>(request.height_px());

  scene.samples = request.samples() == 0 ? kDefaultSamples : static_cast<int>(request.samples());
  if (scene.samples != 1 && scene.samples != 2 && scene.samples != 4 && scene.samples != 8) {
    return invalid_argument("samples: expected 1, 2, 4 or 8 (0 = 4), got " + std::to_string(request.samples()));
  }

  if (request.background_rgba_size() != 0) {
    if (request.background_rgba_size() != 4) {
      return invalid_argument("background_rgba: expected 4 values (RGBA), got " +
                              std::to_string(request.background_rgba_size()));
    }
    for (int c = 0; c < 4; ++c) {
      const float v = request.background_rgba(c);
      if (!(v >= 0 && v <= 1)) {
        return invalid_argument("background_rgba[" + std::to_string(c) + "]: expected a value in [0, 1], got " +
                                std::to_string(v));
      }
      scene.background[c] = v;
    }
  }

  switch (request.shading()) {
    case Request::SHADING_UNSPECIFIED:
    case Request::SHADING_BLINN_PHONG:
      scene.shading = render::Shading::kBlinnPhong;
      break;
    case Request::SHADING_LAMBERT:
      scene.shading = render::Shading::kLambert;
      break;
    default:
      return invalid_argument("shading: unknown value " + std::to_string(static_cast<int>(request.shading())));
  }

  for (const auto& [field, value] : {std::pair{"tolerance_px", request.tolerance_px()},
                                     std::pair{"pixel_tolerance", request.pixel_tolerance()}}) {
    if (!std::isfinite(value) || value < 0) {
      return invalid_argument(std::string(field) + ": expected a finite value ≥ 0 (0 = full detail), got " +
                              std::to_string(value));
    }
  }
  if (request.tolerance_px() != 0 && request.pixel_tolerance() != 0 &&
      request.tolerance_px() != request.pixel_tolerance()) {
    return invalid_argument("tolerance_px: " + format_number(request.tolerance_px()) +
                            " disagrees with pixel_tolerance (its deprecated name), " +
                            format_number(request.pixel_tolerance()) + "; send tolerance_px only");
  }

  if (request.has_camera()) {
    const v1::Camera& c = request.camera();
    render::Camera camera;
    for (const auto& [field, values, out] :
         {std::tuple{"camera.eye", &c.eye(), &camera.eye}, {"camera.target", &c.target(), &camera.target},
          {"camera.up", &c.up(), &camera.up}}) {
      if (values->size() != 3) {
        return invalid_argument(std::string(field) + ": expected 3 values, got " + std::to_string(values->size()));
      }
      *out = Eigen::Vector3d((*values)[0], (*values)[1], (*values)[2]);
    }
    camera.vertical_fov_rad = c.vertical_fov_rad();
    if (Status valid = render::validate_camera(camera, "camera"); !valid.ok()) return to_grpc_status(valid.error());
    scene.camera = camera;
  }
  return grpc::Status::OK;
}

float thumbnail_tolerance_px(const Request& request) {
  return request.tolerance_px() != 0 ? request.tolerance_px() : request.pixel_tolerance();
}

}  // namespace animspace::server
