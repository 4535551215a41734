#include "core/animspace/secondary_motion.h"

#include <cassert>
#include <cmath>
#include <random>

namespace animspace::animation_space {

int add_secondary_motion(const PointMatrix& rest, const SecondaryMotionOptions& options, uint64_t seed,
                         FrameMatrix& frames) {
  const long N = rest.rows();
  assert(N > 0 && frames.cols() == 3 * N);
  const Eigen::Vector3f extent = rest.colwise().maxCoeff() - rest.colwise().minCoeff();
  const double diagonal = static_cast<double>(extent.norm());
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal;
  std::uniform_int_distribution<long> vertex(0, N - 1);
  int bumped = 0;
  for (long f = 0; f < frames.rows(); ++f) {
    // Every draw is made for every frame, so that frame f's bump does not depend on the others'.
    const bool bump = unit(random) < options.bumped_fraction;
    const long centre = vertex(random);
    const double amplitude = unit(random) * options.max_amplitude_diag * diagonal;
    const double sigma =
        (options.min_radius_diag + unit(random) * (options.max_radius_diag - options.min_radius_diag)) * diagonal;
    Eigen::Vector3d direction(normal(random), normal(random), normal(random));
    if (!bump || !(direction.norm() > 0) || !(sigma > 0)) continue;
    direction.normalize();
    ++bumped;
    const Eigen::RowVector3d c = rest.row(centre).cast<double>();
    for (long i = 0; i < N; ++i) {
      const double d2 = (rest.row(i).cast<double>() - c).squaredNorm();
      const double weight = std::exp(-d2 / (2 * sigma * sigma));
      if (weight < 1e-6) continue;  // below float resolution of any frame worth testing
      for (int k = 0; k < 3; ++k) frames(f, 3 * i + k) += static_cast<float>(amplitude * weight * direction(k));
    }
  }
  return bumped;
}

}  // namespace animspace::animation_space
