// Radiance as colours: the white point is the 99th percentile of the points' brightest channels
// (counted here on a known ranking), negative radiance shows black, and the scene is exposed,
// sRGB-encoded and unlit.
#include "core/thumbnail/radiance_colours.h"

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::thumbnail {
namespace {

TEST(RadianceColours, WhitePointIsThe99thPercentileOfTheBrightestChannels) {
  // 201 points whose brightest channel is 0, 1, …, 200 in a shuffled order (the other channels
  // dimmer, in rotating positions): rank ⌊0.99 · 200⌋ = 198 holds 198.
  std::vector<int> order(201);
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), std::mt19937(7));
  PointMatrix colours(201, 3);
  for (int i = 0; i < 201; ++i) {
    const float top = static_cast<float>(order[static_cast<size_t>(i)]);
    colours.row(i) << top / 2, top / 3, top / 4;
    colours(i, i % 3) = top;
  }
  EXPECT_EQ(radiance_white_point(colours), 198);
}

TEST(RadianceColours, WhitePointIsOneWithoutLight) {
  EXPECT_EQ(radiance_white_point(PointMatrix(0, 3)), 1);
  EXPECT_EQ(radiance_white_point(PointMatrix::Zero(10, 3)), 1);
  EXPECT_EQ(radiance_white_point(PointMatrix::Constant(10, 3, -2)), 1);
  EXPECT_EQ(radiance_white_point(PointMatrix::Constant(1, 3, 0.5f)), 0.5);
}

TEST(RadianceColours, NegativeRadianceIsBlackAndTheSceneIsExposedUnlitInSrgb) {
  PointMatrix radiance(3, 3);
  radiance << 0.5f, -0.25f, 2, -1, -1, -1, 4, 1, 0;
  const PointMatrix clamped = radiance.cwiseMax(0.0f);

  render::Scene given;
  radiance_colours(radiance, 8, given);
  EXPECT_EQ(given.vertex_colours, clamped);
  EXPECT_FLOAT_EQ(given.exposure, 1.0f / 8);
  EXPECT_TRUE(given.srgb);
  EXPECT_EQ(given.shading, render::Shading::kUnlit);

  // White unset: the percentile of the clamped colours (rank ⌊0.99 · 2⌋ = 1 of {0, 2, 4}).
  render::Scene automatic;
  radiance_colours(radiance, 0, automatic);
  EXPECT_EQ(automatic.vertex_colours, clamped);
  EXPECT_FLOAT_EQ(automatic.exposure, 1.0f / 2);
  // All dark: exposure 1, not a division by zero.
  render::Scene dark;
  radiance_colours(PointMatrix::Constant(4, 3, -0.1f), 0, dark);
  EXPECT_EQ(dark.vertex_colours, PointMatrix::Zero(4, 3));
  EXPECT_FLOAT_EQ(dark.exposure, 1);
}

}  // namespace
}  // namespace animspace::thumbnail
