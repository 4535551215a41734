// One discrete level for a viewer that cannot geomorph: eq. 7.2 at a distance, worked by hand,
// and the vertex budget, against the real arm levels.
#include "core/lod/selection.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/animspace/tangents.h"
#include "core/lod/simplify.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

LodLevels fake_levels() {
  LodLevels lods;
  for (const double error : {0.0, 0.01, 0.02, 0.04}) {
    LodLevel level;
    level.epsilon = error;
    lods.levels.push_back(level);
  }
  return lods;
}

TEST(LodSelection, PixelToleranceIsEquation72AtTheSpheresNearestDepth) {
  const LodLevels lods = fake_levels();
  // p = 1.5 px, w = 1000 px, 2θ = 60°, sphere radius 2 at distance 12: d = 10, so
  // ε = 2·1.5·10·sin 30° / 1000 = 0.015, between ε¹ and ε²: the finer one, level 1.
  PixelTolerance view;
  view.tolerance_px = 1.5;
  view.viewport_width_px = 1000;
  view.horizontal_fov_rad = std::numbers::pi / 3;
  view.distance = 12;
  auto choice = level_for_view(lods, view, 2);
  ASSERT_TRUE(choice.ok());
  EXPECT_EQ(choice->level, 1);
  EXPECT_NEAR(choice->tolerated_error, 0.015, 1e-15);

  // Just past ε² (d = 40/3 gives ε = 0.02) reaches level 2; far away, the coarsest.
  view.distance = 2 + 40.0 / 3 + 1e-9;
  EXPECT_EQ(level_for_view(lods, view, 2)->level, 2);
  view.distance = 1e6;
  EXPECT_EQ(level_for_view(lods, view, 2)->level, 3);

  // Inside (or on) the sphere: full detail, nothing tolerated.
  view.distance = 2;
  choice = level_for_view(lods, view, 2);
  ASSERT_TRUE(choice.ok());
  EXPECT_EQ(choice->level, 0);
  EXPECT_EQ(choice->tolerated_error, 0);

  // A bad view is refused even when the camera is inside the sphere.
  view.tolerance_px = -1;
  auto refused = level_for_view(lods, view, 2);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().message.rfind("tolerance_px: expected", 0), 0u) << refused.error().message;
  view.tolerance_px = 1;
  view.distance = -3;
  refused = level_for_view(lods, view, 2);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().message.rfind("distance: expected a finite value > 0", 0), 0u) << refused.error().message;
}

TEST(LodSelection, VertexBudgetTakesTheFinestLevelThatFits) {
  const testing::LodCase c = testing::arm_lod_case();
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok());
  const LodLevels lods = make_levels(*pm);
  ASSERT_GT(lods.count(), 2);
  for (int l = 0; l < lods.count(); ++l) {
    const int vertices = lods.levels[static_cast<size_t>(l)].model.vertex_count();
    auto exact = level_for_vertex_budget(lods, vertices);
    ASSERT_TRUE(exact.ok());
    // The finest level with at most that many vertices: l itself, or a finer one of equal size.
    EXPECT_LE(*exact, l);
    EXPECT_EQ(lods.levels[static_cast<size_t>(*exact)].model.vertex_count(), vertices);
  }
  EXPECT_EQ(*level_for_vertex_budget(lods, 1 << 30), 0);
  const int coarsest = lods.levels.back().model.vertex_count();
  auto refused = level_for_vertex_budget(lods, coarsest - 1);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kOutOfRange);
  EXPECT_NE(refused.error().message.find("expected at least " + std::to_string(coarsest)), std::string::npos)
      << refused.error().message;
  EXPECT_EQ(refused.error().message.find("build-lod"), std::string::npos) << "it has levels";

  // Issue #55: a model with level 0 alone says so, and how to build levels.
  LodLevels alone;
  alone.levels.push_back(lods.levels.front());
  const int full = alone.levels.front().model.vertex_count();
  refused = level_for_vertex_budget(alone, full - 1);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("the model has only level 0 (full detail)"), std::string::npos)
      << refused.error().message;
  EXPECT_NE(refused.error().message.find("animspace build-lod"), std::string::npos) << refused.error().message;
}

TEST(LodSelection, BoundingSphereIsTheStoredOneOrTheRestPoses) {
  const testing::LodCase c = testing::arm_lod_case();
  container::ModelContainer without;
  animation_space::store(c.model, without);
  auto sphere = model_bounding_sphere(without, c.model, "arm");
  ASSERT_TRUE(sphere.ok()) << sphere.error().message;
  // Every rest vertex inside, and one on the sphere (radius to the farthest vertex).
  const Eigen::MatrixX3d rest = animation_space::rest_positions(c.model);
  const Eigen::VectorXd distances = (rest.rowwise() - sphere->centre.transpose()).rowwise().norm();
  EXPECT_NEAR(distances.maxCoeff(), sphere->radius, 1e-12);

  container::ModelContainer with = without;
  auto stored = animation_space::stored_metrics_from_poses(c.model, c.poses);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  animation_space::store_metrics(*stored, with);
  sphere = model_bounding_sphere(with, c.model, "arm");
  ASSERT_TRUE(sphere.ok());
  EXPECT_EQ(sphere->radius, stored->bounding_sphere.radius);
  EXPECT_EQ(sphere->centre, stored->bounding_sphere.centre);
}

}  // namespace
}  // namespace animspace::lod
