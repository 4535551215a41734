// Localised secondary motion (core/animspace/secondary_motion.h): each bumped frame moves one
// patch of skin along one direction with a Gaussian falloff of rest-pose distance, of a size
// within the options; the rest of the frames are untouched; the same seed gives the same frames.
#include "core/animspace/secondary_motion.h"

#include <cmath>

#include <gtest/gtest.h>

namespace animspace::animation_space {
namespace {

// Points along a line, 0.01 apart: diagonal 1 (from x = 0 to x = 1).
PointMatrix line(int count) {
  PointMatrix rest = PointMatrix::Zero(count, 3);
  for (int i = 0; i < count; ++i) rest(i, 0) = static_cast<float>(i) / static_cast<float>(count - 1);
  return rest;
}

TEST(SecondaryMotion, EachBumpIsOnePatchAlongOneDirectionWithAGaussianFalloff) {
  const PointMatrix rest = line(101);
  SecondaryMotionOptions options;  // amplitude ≤ 0.03, σ in [0.02, 0.06] of the diagonal (1)
  FrameMatrix frames = FrameMatrix::Zero(2000, 3 * 101);
  const int bumped = add_secondary_motion(rest, options, 52, frames);
  // Binomial(2000, 1/2): 4.5 standard deviations (0.011 each) either side.
  EXPECT_GT(bumped, 900);
  EXPECT_LT(bumped, 1100);
  int moved_frames = 0;
  for (long f = 0; f < frames.rows(); ++f) {
    const Eigen::Map<const Eigen::Matrix<float, 3, Eigen::Dynamic>> d(frames.row(f).data(), 3, 101);
    const Eigen::VectorXf size = d.colwise().norm();
    long centre = 0;
    const float amplitude = size.maxCoeff(&centre);
    if (amplitude == 0) continue;
    ++moved_frames;
    ASSERT_LE(amplitude, 0.03f * (1 + 1e-5f)) << "frame " << f;
    const Eigen::Vector3f u = d.col(centre) / amplitude;
    // σ from a neighbour's falloff, then every point on the same Gaussian along the same u.
    const long other = centre + (centre < 50 ? 1 : -1);
    const double ratio = size(other) / amplitude;
    ASSERT_GT(ratio, 0) << "frame " << f;
    const double sigma = std::sqrt(-0.01 * 0.01 / (2 * std::log(ratio)));
    EXPECT_GE(sigma, 0.02 * (1 - 1e-3)) << "frame " << f;
    EXPECT_LE(sigma, 0.06 * (1 + 1e-3)) << "frame " << f;
    for (long i = 0; i < 101; ++i) {
      const double distance = 0.01 * static_cast<double>(i - centre);
      const double expected = amplitude * std::exp(-distance * distance / (2 * sigma * sigma));
      const double tolerance = 1e-6 + 1e-4 * amplitude;
      ASSERT_NEAR(d.col(i).dot(u), expected < 1e-6 * amplitude ? 0.0 : expected, tolerance) << "frame " << f << " point " << i;
      ASSERT_NEAR((d.col(i) - d.col(i).dot(u) * u).norm(), 0.0, tolerance) << "frame " << f << " point " << i;
    }
  }
  EXPECT_EQ(moved_frames, bumped) << "an unbumped frame is untouched";

  FrameMatrix again = FrameMatrix::Zero(2000, 3 * 101);
  add_secondary_motion(rest, options, 52, again);
  EXPECT_TRUE(again == frames);
}

}  // namespace
}  // namespace animspace::animation_space
