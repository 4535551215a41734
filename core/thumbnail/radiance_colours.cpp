#include "core/thumbnail/radiance_colours.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace animspace::thumbnail {

double radiance_white_point(const PointMatrix& colours) {
  if (colours.rows() == 0) return 1.0;
  std::vector<double> largest(static_cast<size_t>(colours.rows()));
  for (Eigen::Index i = 0; i < colours.rows(); ++i) largest[static_cast<size_t>(i)] = colours.row(i).maxCoeff();
  auto at = largest.begin() + static_cast<long>(0.99 * static_cast<double>(largest.size() - 1));
  std::nth_element(largest.begin(), at, largest.end());
  return *at <= 0 ? 1.0 : *at;
}

void radiance_colours(PointMatrix radiance, double white_radiance, render::Scene& scene) {
  assert(std::isfinite(white_radiance) && white_radiance >= 0);
  radiance = radiance.cwiseMax(0.0f);
  const double white = white_radiance > 0 ? white_radiance : radiance_white_point(radiance);
  scene.vertex_colours = std::move(radiance);
  scene.exposure = static_cast<float>(1.0 / white);
  scene.srgb = true;
  scene.shading = render::Shading::kUnlit;
}

}  // namespace animspace::thumbnail
