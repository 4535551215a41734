#include "core/animspace/model.h"

#include <random>

#include <gtest/gtest.h>

#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

using testing::random_model;
using testing::random_pose;
using testing::random_skeleton;

TEST(SkeletonTest, GlobalAndJointTransformsAreInverse) {
  const Skeleton skeleton = random_skeleton(7, 1);
  ASSERT_TRUE(validate(skeleton).ok());
  std::mt19937_64 engine(2);
  const TransformList globals = random_pose(skeleton, engine, 3.0);
  const TransformList again = global_transforms(skeleton, joint_transforms(skeleton, globals));
  for (size_t j = 0; j < globals.size(); ++j) EXPECT_TRUE(again[j].isApprox(globals[j], 1e-12)) << j;
}

TEST(SkeletonTest, RejectsParentAfterChildAndNonAffineRest) {
  Skeleton skeleton = random_skeleton(3, 1);
  skeleton.parents[1] = 2;
  EXPECT_FALSE(validate(skeleton).ok());
  skeleton = random_skeleton(3, 1);
  skeleton.rest[2](3, 0) = 0.5;
  const Status status = validate(skeleton);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("bone 2"), std::string::npos) << status.error().message;
}

// v = Σ_j G_j p_j checked against the dense animation matrix G (eq. 3.2) built independently.
TEST(AnimationSpaceModelTest, EvaluationEqualsDenseAnimationProjection) {
  const Skeleton skeleton = random_skeleton(6, 3);
  const AnimationSpaceModel model = random_model(skeleton, 200, 4);
  ASSERT_TRUE(validate(model).ok());
  std::mt19937_64 engine(5);
  const TransformList globals = random_pose(skeleton, engine, 2.0);
  Eigen::MatrixXd G(4, 4 * skeleton.bone_count());
  for (int j = 0; j < skeleton.bone_count(); ++j) G.middleCols<4>(4 * j) = globals[static_cast<size_t>(j)];
  PointMatrix posed;
  evaluate(model, globals, posed);
  for (int i = 0; i < model.vertex_count(); ++i) {
    const Eigen::Vector4d v = G * dense_position(model, i);
    EXPECT_NEAR(v(3), 1.0, 1e-12);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(posed(i, c), v(c), 1e-5 * (1 + std::abs(v(c))));
  }
}

// Local fail-through poses only the vertices it names: each equals the dense projection G·p_i.
TEST(AnimationSpaceModelTest, EvaluatingListedVerticesEqualsTheDenseProjectionOfEach) {
  const Skeleton skeleton = random_skeleton(6, 3);
  const AnimationSpaceModel model = random_model(skeleton, 200, 4);
  std::mt19937_64 engine(6);
  const TransformList globals = random_pose(skeleton, engine, 2.0);
  Eigen::MatrixXd G(4, 4 * skeleton.bone_count());
  for (int j = 0; j < skeleton.bone_count(); ++j) G.middleCols<4>(4 * j) = globals[static_cast<size_t>(j)];
  const std::vector<int> vertices = {0, 17, 18, 150, 199};
  PointMatrix posed;
  evaluate_vertices(model, globals, vertices, posed);
  ASSERT_EQ(posed.rows(), 5);
  for (size_t j = 0; j < vertices.size(); ++j) {
    const Eigen::Vector4d v = G * dense_position(model, vertices[j]);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(posed(static_cast<long>(j), c), v(c), 1e-5 * (1 + std::abs(v(c))));
  }
  evaluate_vertices(model, globals, {}, posed);
  EXPECT_EQ(posed.rows(), 0);
}

// Large enough to run on several threads: chunked evaluation must equal a plain loop.
TEST(AnimationSpaceModelTest, ThreadedEvaluationMatchesSerialSum) {
  const Skeleton skeleton = random_skeleton(10, 6);
  const AnimationSpaceModel model = random_model(skeleton, 60000, 7);
  std::mt19937_64 engine(8);
  const TransformList globals = random_pose(skeleton, engine, 1.0);
  PointMatrix posed;
  evaluate(model, globals, posed);
  for (int i = 0; i < model.vertex_count(); i += 997) {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      v += globals[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] * model.positions.col(k);
    }
    EXPECT_LT((posed.row(i).cast<double>().transpose() - v.head<3>()).norm(), 1e-5) << i;
  }
}

TEST(AnimationSpaceModelTest, ValidateNamesVertexWithWrongWeight) {
  AnimationSpaceModel model = random_model(random_skeleton(4, 9), 10, 10);
  model.positions(3, model.influences.begin(6)) += 0.5;
  const Status status = validate(model);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("vertex 6"), std::string::npos) << status.error().message;
}

TEST(AnimationSpaceModelTest, NormalsAreCrossProductOfProjectedTangents) {
  const Skeleton skeleton = random_skeleton(3, 11);
  AnimationSpaceModel model = random_model(skeleton, 50, 12);
  std::mt19937_64 engine(13);
  std::normal_distribution<double> normal;
  model.tangent_s.resize(4, model.positions.cols());
  model.tangent_t.resize(4, model.positions.cols());
  for (Eigen::Index k = 0; k < model.positions.cols(); ++k) {
    model.tangent_s.col(k) << normal(engine), normal(engine), normal(engine), 0.0;
    model.tangent_t.col(k) << normal(engine), normal(engine), normal(engine), 0.0;
  }
  ASSERT_TRUE(validate(model).ok());
  const TransformList globals = random_pose(skeleton, engine, 1.0);
  PointMatrix normals;
  evaluate_normals(model, globals, normals);
  for (int i = 0; i < model.vertex_count(); ++i) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero(), t = Eigen::Vector3d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      const Transform& G = globals[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])];
      s += (G * model.tangent_s.col(k)).head<3>();
      t += (G * model.tangent_t.col(k)).head<3>();
    }
    const Eigen::Vector3d n = normals.row(i).cast<double>().transpose();
    EXPECT_NEAR(n.norm(), 1.0, 1e-6);
    EXPECT_NEAR(n.dot(s), 0.0, 1e-5 * s.norm());
    EXPECT_NEAR(n.dot(t), 0.0, 1e-5 * t.norm());
    EXPECT_GT(n.dot(s.cross(t)), 0.0);
  }
}

}  // namespace
}  // namespace animspace::animation_space
