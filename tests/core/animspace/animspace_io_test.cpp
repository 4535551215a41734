#include "core/animspace/animspace_io.h"

#include <random>

#include <gtest/gtest.h>

#include "core/model/model_info.h"
#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

AnimationSpaceModel small_model() {
  AnimationSpaceModel model = testing::random_model(testing::random_skeleton(5, 21), 40, 22);
  model.faces.resize(2, 3);
  model.faces << 0, 1, 2, 2, 1, 3;
  return model;
}

TEST(AnimationSpaceIoTest, RoundTripThroughBytesIsExact) {
  const AnimationSpaceModel model = small_model();
  container::ModelContainer out;
  store(model, out);
  auto parsed = container::parse(container::serialize(out), "memory");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  auto info = model::describe(*parsed, "memory");
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, container::ModelKind::kAnimationSpace);
  EXPECT_EQ(info->point_count, 40);
  EXPECT_EQ(info->bone_count, 5);
  auto loaded = load(*parsed, "memory");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->influences.offsets, model.influences.offsets);
  EXPECT_EQ(loaded->influences.bones, model.influences.bones);
  EXPECT_EQ(loaded->positions, model.positions);
  EXPECT_EQ(loaded->skeleton.parents, model.skeleton.parents);
  for (int j = 0; j < 5; ++j) EXPECT_EQ(loaded->skeleton.rest[static_cast<size_t>(j)], model.skeleton.rest[static_cast<size_t>(j)]);
  EXPECT_EQ(loaded->faces, model.faces);
  EXPECT_FALSE(loaded->has_tangents());
}

TEST(AnimationSpaceIoTest, RestPointsAreTheRestPoseEvaluation) {
  const AnimationSpaceModel model = small_model();
  container::ModelContainer out;
  store(model, out);
  auto rest = out.points(container::sections::kRestPoints);
  ASSERT_TRUE(rest.ok());
  for (int i = 0; i < model.vertex_count(); ++i) {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      v += model.skeleton.rest[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] * model.positions.col(k);
    }
    EXPECT_LT((rest->row(i).cast<double>().transpose() - v.head<3>()).norm(), 1e-5);
  }
}

TEST(AnimationSpaceIoTest, RefusesPositionsOfTheWrongShapeNamingTheSection) {
  container::ModelContainer out;
  store(small_model(), out);
  out.set_matrix(sections::kPositions, container::Float64Matrix::Zero(3, 4).eval());
  const auto info = model::describe(out, "bad.anim");
  ASSERT_FALSE(info.ok());
  EXPECT_NE(info.error().message.find("animspace.positions"), std::string::npos) << info.error().message;
  const auto loaded = load(out, "bad.anim");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().code, ErrorCode::kInvalidArgument);
}

TEST(AnimationSpaceIoTest, RefusesAWeightThatIsNotOne) {
  AnimationSpaceModel model = small_model();
  container::ModelContainer out;
  store(model, out);
  container::Float64Matrix positions = model.positions.transpose();
  positions(0, 3) += 0.25;
  out.set_matrix(sections::kPositions, positions);
  const auto loaded = load(out, "bad.anim");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("bad.anim: vertex 0"), std::string::npos) << loaded.error().message;
}

}  // namespace
}  // namespace animspace::animation_space

namespace animspace::animation_space {
namespace {

TEST(AnimationSpaceIoTest, MetricsRoundTripAndTheSphereHoldsInTheExamplePoses) {
  const AnimationSpaceModel model = small_model();
  std::mt19937_64 engine(23);
  std::vector<TransformList> poses;
  for (int p = 0; p < 50; ++p) poses.push_back(testing::random_pose(model.skeleton, engine, 1.0));
  auto stored = stored_metrics_from_poses(model, poses);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  container::ModelContainer out;
  store(model, out);
  store_metrics(*stored, out);
  auto parsed = container::parse(container::serialize(out), "memory");
  ASSERT_TRUE(parsed.ok());
  auto loaded = load_metrics(*parsed, model.bone_count(), "memory");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->metrics.P, stored->metrics.P);
  EXPECT_EQ(loaded->bounding_sphere.radius, stored->bounding_sphere.radius);
  // Every vertex of every example pose lies inside the stored sphere.
  PointMatrix posed;
  for (const auto& pose : poses) {
    evaluate(model, pose, posed);
    for (int i = 0; i < posed.rows(); ++i) {
      EXPECT_LE((posed.row(i).cast<double>().transpose() - loaded->bounding_sphere.centre).norm(),
                loaded->bounding_sphere.radius * (1 + 1e-6));
    }
  }
  container::ModelContainer bare;
  store(model, bare);
  EXPECT_EQ(load_metrics(bare, model.bone_count(), "bare").error().code, ErrorCode::kNotFound);
}

}  // namespace
}  // namespace animspace::animation_space
