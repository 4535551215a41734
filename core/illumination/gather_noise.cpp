#include "core/illumination/gather_noise.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace animspace::illumination {

std::vector<int> spread_points(int point_count, int count) {
  std::vector<int> points;
  if (point_count <= 0 || count <= 0) return points;
  if (count >= point_count) count = point_count;
  points.reserve(static_cast<size_t>(count));
  for (int k = 0; k < count; ++k) {
    points.push_back(static_cast<int>((2 * static_cast<int64_t>(k) + 1) * point_count / (2 * static_cast<int64_t>(count))));
  }
  return points;
}

double relative_rms_difference(const Eigen::VectorXf& estimate, const Eigen::VectorXf& reference) {
  assert(estimate.size() == reference.size());
  if (reference.size() == 0) return 0;
  const double mean = reference.cast<double>().mean();
  if (!(mean > 0)) return 0;
  return std::sqrt((estimate - reference).cast<double>().array().square().mean()) / mean;
}

double max_error_over_max(const Eigen::VectorXf& estimate, const Eigen::VectorXf& reference) {
  assert(estimate.size() == reference.size() && reference.size() % 3 == 0);
  if (reference.size() == 0) return 0;
  const Eigen::Map<const Eigen::Matrix3Xf> e(estimate.data(), 3, estimate.size() / 3);
  const Eigen::Map<const Eigen::Matrix3Xf> r(reference.data(), 3, reference.size() / 3);
  const double largest = r.colwise().norm().maxCoeff();
  return largest > 0 ? (e - r).colwise().norm().maxCoeff() / largest : 0;
}

double light_roughness(const IlluminationEngine& engine, const PointLight& light, const Eigen::Vector3d& step,
                       int count, const GatherOptions& gather, const std::vector<int>& points) {
  assert(count >= 3);
  std::vector<Eigen::VectorXf> frames(static_cast<size_t>(count));
  double sum = 0;
  for (int i = 0; i < count; ++i) {
    PointLight moved = light;
    moved.position += (i - 0.5 * (count - 1)) * step;
    engine.indirect({moved}, gather, points, frames[static_cast<size_t>(i)]);
    sum += frames[static_cast<size_t>(i)].cast<double>().sum();
  }
  const double mean = sum / (static_cast<double>(count) * static_cast<double>(frames[0].size()));
  if (!(mean > 0) || frames[0].size() == 0) return 0;
  double squares = 0;
  for (int i = 1; i + 1 < count; ++i) {
    const auto s = static_cast<size_t>(i);
    squares += (frames[s - 1] - 2 * frames[s] + frames[s + 1]).cast<double>().squaredNorm();
  }
  return std::sqrt(squares / (static_cast<double>(count - 2) * static_cast<double>(frames[0].size()))) / mean;
}

}  // namespace animspace::illumination
