// The readers against the real reference data in ../shared/data (see its README); every test
// skips when that folder is absent.
#include <string>

#include <gtest/gtest.h>

#include "core/mesh_io/libigl_rig.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

#define ANIMSPACE_REQUIRE_SHARED_DATA(dir)                                               \
  const auto dir = animspace::testing::shared_data_dir();                                \
  if (!dir) GTEST_SKIP() << "reference data folder absent (set ANIMSPACE_SHARED_DATA)"

TEST(MeshIoSharedData, CowRestMesh) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto cow = read_triangle_mesh(*data / "cow-rig" / "cow.obj");
  ASSERT_TRUE(cow.ok()) << cow.error().message;
  EXPECT_EQ(cow->V.rows(), 11666);
  EXPECT_EQ(cow->F.rows(), 23328);
}

TEST(MeshIoSharedData, CowDmatWeightsArePerVertexAndSumToOne) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto W = read_dmat(*data / "cow-rig" / "cow.DMAT");
  ASSERT_TRUE(W.ok()) << W.error().message;
  // Header `15 11666` is `cols rows`: #V by #B.
  ASSERT_EQ(W->rows(), 11666);
  ASSERT_EQ(W->cols(), 15);
  EXPECT_LT((W->rowwise().sum().array() - 1.0).abs().maxCoeff(), 1e-9);
  EXPECT_GE(W->minCoeff(), 0.0);
  EXPECT_LE(W->maxCoeff(), 1.0);
}

TEST(MeshIoSharedData, CowSkeleton) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto skeleton = read_tgf(*data / "cow-rig" / "cow.tgf");
  ASSERT_TRUE(skeleton.ok()) << skeleton.error().message;
  EXPECT_EQ(skeleton->joints.rows(), 16);
  ASSERT_EQ(skeleton->bones.rows(), 15);
  EXPECT_EQ(skeleton->bones.row(0), Eigen::RowVector2i(0, 1));
  EXPECT_EQ(skeleton->bones.row(14), Eigen::RowVector2i(14, 15));
}

TEST(MeshIoSharedData, CowPosesAreLinearBlendSkinningOfTheRestMesh) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto rest = read_triangle_mesh(*data / "cow-rig" / "cow.obj");
  ASSERT_TRUE(rest.ok()) << rest.error().message;
  const auto W = read_dmat(*data / "cow-rig" / "cow.DMAT");
  ASSERT_TRUE(W.ok()) << W.error().message;
  const Eigen::MatrixXd V = rest->V.cast<double>();
  const double diagonal = (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
  Eigen::MatrixXd V1(V.rows(), 4);  // [v 1], #V by 4
  V1 << V, Eigen::VectorXd::Ones(V.rows());
  for (int pose = 1; pose <= 7; ++pose) {
    const auto name = "cow-" + std::to_string(pose);
    const auto T = read_tmat(*data / "cow-rig" / "poses" / (name + ".Tmat"));
    ASSERT_TRUE(T.ok()) << T.error().message;
    ASSERT_EQ(T->size(), 15u);
    const auto posed = read_triangle_mesh(*data / "cow-rig" / "poses" / (name + ".obj"));
    ASSERT_TRUE(posed.ok()) << posed.error().message;
    ASSERT_EQ(posed->V.rows(), V.rows());
    // posed_v = Σ_j w_vj · [v 1] · T_j (README, row-vector form).
    Eigen::MatrixXd skinned = Eigen::MatrixXd::Zero(V.rows(), 3);
    for (int j = 0; j < 15; ++j) skinned += W->col(j).asDiagonal() * (V1 * (*T)[static_cast<size_t>(j)]);
    const double deviation = (skinned - posed->V.cast<double>()).rowwise().norm().maxCoeff();
    EXPECT_LT(deviation / diagonal, 1e-3) << name;
  }
}

TEST(MeshIoSharedData, HorseGallopPointCache) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto cache = read_pc2(*data / "horse-gallop" / "frames.pc2");
  ASSERT_TRUE(cache.ok()) << cache.error().message;
  EXPECT_EQ(cache->num_frames(), 48);
  EXPECT_EQ(cache->num_points, 8431);
  const auto reference = read_triangle_mesh(*data / "horse-gallop" / "reference.obj");
  ASSERT_TRUE(reference.ok()) << reference.error().message;
  ASSERT_EQ(reference->V.rows(), cache->num_points);
  // reference.obj holds the first frame's vertices, in the cache's order.
  const double diagonal = (reference->V.colwise().maxCoeff() - reference->V.colwise().minCoeff()).norm();
  EXPECT_LT((cache->frame(0) - reference->V).cwiseAbs().maxCoeff(), 1e-5 * diagonal);
}

TEST(MeshIoSharedData, CranePointCache) {
  ANIMSPACE_REQUIRE_SHARED_DATA(data);
  const auto cache = read_pc2(*data / "crane" / "frames.pc2");
  ASSERT_TRUE(cache.ok()) << cache.error().message;
  EXPECT_EQ(cache->num_frames(), 175);
  EXPECT_EQ(cache->num_points, 10002);
  const auto reference = read_triangle_mesh(*data / "crane" / "reference.obj");
  ASSERT_TRUE(reference.ok()) << reference.error().message;
  EXPECT_EQ(reference->V.rows(), cache->num_points);
}

}  // namespace
}  // namespace animspace::mesh_io
