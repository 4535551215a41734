// A skinned model posed for a thumbnail: full detail without a tolerance; with one, the level
// eq. 7.2 gives for a view worked out here (the camera's horizontal field of view and the
// distance to the posed mesh's bounding box centre), posed by hand as v = Σ_j G_j p_j.
#include "core/thumbnail/skinned_scene.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "core/lod/selection.h"
#include "core/lod/simplify.h"
#include "core/render/camera.h"
#include "harness/lod_fixtures.h"

namespace animspace::thumbnail {
namespace {

namespace as = animation_space;
using testing::arm_lod_case;
using testing::LodCase;

// v = Σ_j G_j p_j for every vertex (eq. 3.1), in double.
Eigen::MatrixX3d posed_by_hand(const as::AnimationSpaceModel& model, const as::TransformList& G) {
  Eigen::MatrixX3d out(model.vertex_count(), 3);
  for (int v = 0; v < model.vertex_count(); ++v) {
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(v); k < model.influences.end(v); ++k) {
      sum += G[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] * model.positions.col(k);
    }
    out.row(v) = sum.head<3>().transpose();
  }
  return out;
}

class SkinnedSceneTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    arm_ = new LodCase(arm_lod_case());
    auto pm = lod::build_progressive_mesh(arm_->model, arm_->metrics, {});
    ASSERT_TRUE(pm.ok());
    lods_ = new lod::LodLevels(lod::make_levels(*pm));
  }
  static void TearDownTestSuite() {
    delete lods_;
    delete arm_;
  }
  static render::Scene scene_of_size(int width, int height) {
    render::Scene scene;
    scene.width = width;
    scene.height = height;
    return scene;
  }
  static LodCase* arm_;
  static lod::LodLevels* lods_;
};
LodCase* SkinnedSceneTest::arm_ = nullptr;
lod::LodLevels* SkinnedSceneTest::lods_ = nullptr;

TEST_F(SkinnedSceneTest, WithoutAToleranceTheModelIsPosedAtFullDetail) {
  const as::TransformList& G = arm_->poses[5];
  const lod::LodLevels* none = nullptr;
  for (const lod::LodLevels* lods : {none, static_cast<const lod::LodLevels*>(lods_)}) {
    render::Scene scene = scene_of_size(64, 64);
    auto level = pose_skinned(arm_->model, lods, G, 0, scene);
    ASSERT_TRUE(level.ok());
    EXPECT_EQ(*level, 0);
    EXPECT_LT((scene.points.cast<double>() - posed_by_hand(arm_->model, G)).cwiseAbs().maxCoeff(), 1e-5);
    EXPECT_EQ(scene.faces, arm_->model.faces);
    EXPECT_FALSE(scene.camera);  // left for the renderer to frame
    EXPECT_EQ(scene.normals.rows(), 0);  // no tangents: the renderer computes normals from faces
  }
  // A tolerance with no levels to choose from is full detail too.
  render::Scene scene = scene_of_size(64, 64);
  EXPECT_EQ(*pose_skinned(arm_->model, nullptr, G, 50, scene), 0);
  EXPECT_FALSE(scene.camera);
}

TEST_F(SkinnedSceneTest, AToleranceDrawsTheLevelEquation72GivesForTheThumbnailsCamera) {
  ASSERT_GE(lods_->count(), 3);
  const as::TransformList& G = arm_->poses[12];
  const Eigen::MatrixX3d full = posed_by_hand(arm_->model, G);
  const Eigen::Vector3d centre = (full.colwise().minCoeff() + full.colwise().maxCoeff()).transpose() / 2;
  const double radius = (full.rowwise() - centre.transpose()).rowwise().norm().maxCoeff();
  const int width = 200, height = 100;
  const double vertical_fov = 0.6;
  const double horizontal_fov = 2 * std::atan(2.0 * std::tan(vertical_fov / 2));

  int coarser_seen = 0;
  for (const double distance : {3.0, 10.0, 40.0, 200.0}) {
    render::Scene scene = scene_of_size(width, height);
    scene.camera = render::Camera{centre + Eigen::Vector3d(0, 0, distance * radius), centre,
                                  Eigen::Vector3d::UnitY(), vertical_fov};
    lod::PixelTolerance view;
    view.tolerance_px = 2;
    view.viewport_width_px = width;
    view.horizontal_fov_rad = horizontal_fov;
    view.distance = distance * radius;
    const int expected = lod::level_for_view(*lods_, view, radius)->level;
    coarser_seen += expected > 0;

    auto level = pose_skinned(arm_->model, lods_, G, 2, scene);
    ASSERT_TRUE(level.ok()) << level.error().message;
    EXPECT_EQ(*level, expected) << "distance " << distance;
    const as::AnimationSpaceModel& drawn = lods_->levels[static_cast<size_t>(expected)].model;
    ASSERT_EQ(scene.points.rows(), drawn.vertex_count());
    EXPECT_LT((scene.points.cast<double>() - posed_by_hand(drawn, G)).cwiseAbs().maxCoeff(), 1e-5);
    EXPECT_EQ(scene.faces, drawn.faces);
  }
  EXPECT_GE(coarser_seen, 2);  // the test reaches coarser levels, not only full detail
}

TEST_F(SkinnedSceneTest, WithoutACameraTheSceneIsFramedAroundTheFullDetailMesh) {
  const as::TransformList& G = arm_->poses[3];
  render::Scene scene = scene_of_size(120, 80);
  auto level = pose_skinned(arm_->model, lods_, G, 1, scene);
  ASSERT_TRUE(level.ok());
  ASSERT_TRUE(scene.camera);
  PointMatrix full;
  as::evaluate(arm_->model, G, full);
  const render::Camera framed = *render::frame_bounding_box(full, 120.0 / 80);
  EXPECT_EQ(scene.camera->eye, framed.eye);
  EXPECT_EQ(scene.camera->target, framed.target);
}

TEST_F(SkinnedSceneTest, ANonFinitePoseCannotBeFramed) {
  as::TransformList G = arm_->poses[0];
  G[1](0, 3) = std::numeric_limits<double>::quiet_NaN();
  render::Scene scene = scene_of_size(64, 64);
  auto refused = pose_skinned(arm_->model, lods_, G, 1, scene);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace animspace::thumbnail
