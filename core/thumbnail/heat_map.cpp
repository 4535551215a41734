#include "core/thumbnail/heat_map.h"

#include <cassert>
#include <cmath>
#include <string>

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

}  // namespace animspace::thumbnail
