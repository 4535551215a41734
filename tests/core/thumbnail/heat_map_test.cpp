// The heat map of a cache's error: per-point distances computed here by hand, the scale's order
// of precedence, and the refusal of distances float32 cannot hold.
#include "core/thumbnail/heat_map.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace animspace::thumbnail {
namespace {

PointMatrix rows(std::initializer_list<std::array<float, 3>> values) {
  PointMatrix out(static_cast<Eigen::Index>(values.size()), 3);
  Eigen::Index i = 0;
  for (const auto& v : values) out.row(i++) << v[0], v[1], v[2];
  return out;
}

TEST(HeatMap, HeatIsThePerPointDistanceAndTheScaleTakesTheFirstPositive) {
  const PointMatrix truth = rows({{1, 2, 3}, {0, 0, 0}, {-1, 4, 2}});
  const PointMatrix estimate = rows({{1, 2, 3}, {3, 4, 0}, {-1, 4, 2.5f}});
  const float expected[] = {0, 5, 0.5f};  // |(0,0,0)|, |(−3,−4,0)|, |(0,0,−0.5)|

  struct Case {
    double requested_max, error_tolerance, scale;
  };
  for (const Case c : {Case{2, 0.25, 2}, Case{0, 0.25, 0.25}, Case{0, 0, 5}}) {
    render::Scene scene;
    auto scale = heat_map(truth, estimate, c.requested_max, c.error_tolerance, "full_values", scene);
    ASSERT_TRUE(scale.ok()) << scale.error().message;
    ASSERT_EQ(scene.heat.size(), 3);
    for (int i = 0; i < 3; ++i) EXPECT_FLOAT_EQ(scene.heat[i], expected[i]) << i;
    EXPECT_DOUBLE_EQ(scale->largest_error, 5);
    EXPECT_DOUBLE_EQ(scale->scale_max, c.scale) << c.requested_max << " " << c.error_tolerance;
    EXPECT_FLOAT_EQ(scene.heat_max, static_cast<float>(c.scale));
  }
}

TEST(HeatMap, NoPointsHaveNoError) {
  render::Scene scene;
  auto scale = heat_map(PointMatrix(0, 3), PointMatrix(0, 3), 0, 0, "full_values", scene);
  ASSERT_TRUE(scale.ok());
  EXPECT_EQ(scale->largest_error, 0);
  EXPECT_EQ(scale->scale_max, 0);
  EXPECT_EQ(scene.heat.size(), 0);
}

TEST(HeatMap, ADistanceBeyondFloat32IsRefusedNamingTheField) {
  const float big = std::numeric_limits<float>::max();
  render::Scene scene;
  auto refused = heat_map(rows({{0, 0, 0}, {big, 0, 0}}), rows({{0, 0, 0}, {-big, 0, 0}}), 0, 0, "full_values", scene);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(refused.error().message,
            "full_values: |full − estimate| overflows float32; expected values on the model's scale");
}

}  // namespace
}  // namespace animspace::thumbnail
