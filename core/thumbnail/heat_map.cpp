#include "core/thumbnail/heat_map.h"

#include <cassert>
#include <cmath>
#include <string>

#include "core/render/camera.h"
#include "core/render/heat_legend.h"

namespace animspace::thumbnail {

Result<HeatScale> heat_map(const Eigen::Ref<const PointMatrix>& truth, const Eigen::Ref<const PointMatrix>& estimate,
                           double requested_max, double error_tolerance, std::string_view field, render::Scene& scene) {
  assert(truth.rows() == estimate.rows());
  assert(std::isfinite(requested_max) && requested_max >= 0);
  assert(std::isfinite(error_tolerance) && error_tolerance >= 0);
  scene.heat = (truth - estimate).rowwise().norm();
  HeatScale scale;
  scale.largest_error = scene.heat.size() == 0 ? 0.0 : static_cast<double>(scene.heat.maxCoeff());
  if (!std::isfinite(scale.largest_error)) {
    return make_error(ErrorCode::kInvalidArgument,
                      std::string(field) +
                          ": |full − estimate| overflows float32; expected values on the model's scale");
  }
  scale.scale_max = requested_max;
  if (scale.scale_max == 0) scale.scale_max = error_tolerance;
  if (scale.scale_max == 0) scale.scale_max = scale.largest_error;
  scene.heat_max = static_cast<float>(scale.scale_max);
  return scale;
}

Status frame_beside_heat_legend(render::Scene& scene, int width, int height, double heat_max) {
  if (scene.camera) return {};
  const render::HeatLegendLayout legend = render::heat_legend_layout(width, height, heat_max);
  if (!legend.fits) return {};
  auto camera = render::frame_in_columns(scene.points, width, height, legend.panel_x0);
  if (!camera) return camera.error();
  scene.camera = *camera;
  return {};
}

}  // namespace animspace::thumbnail
