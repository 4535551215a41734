// The server engine a model file carries is built once at load, behind one interface: a PMSC
// model with an animation-space engine poses its frames through it, point by point equal to the
// whole frame; a model without one (cross-PMSC) has none.
#include "core/model/engine.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/demo/demo_repository.h"
#include "core/model/servable.h"
#include "core/pmsc/coordinates.h"

namespace animspace::model {
namespace {

TEST(Engine, APmscModelWithASkeletonPosesThroughItsAnimationSpaceModel) {
  auto container = demo::make_demo_pmsc_engine_container(24);
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto servable = load_servable(*container, "demo");
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  ASSERT_TRUE(servable->engine && servable->animation_space);
  EXPECT_EQ(servable->engine->input(), Engine::Input::kSkeletonPose);
  EXPECT_EQ(input_name(servable->engine->input()), "skeleton_pose");
  EXPECT_EQ(servable->basis_checksum, pmsc::basis_checksum(servable->pmsc->mean, servable->pmsc->basis));

  // A bent pose: every joint rotated about z by a different angle.
  const auto& skeleton = servable->animation_space->skeleton;
  EngineInput input;
  input.globals = animation_space::rest_pose(skeleton);
  for (size_t j = 0; j < input.globals.size(); ++j) {
    const double angle = 0.3 * static_cast<double>(j + 1);
    input.globals[j].topLeftCorner<3, 3>() =
        Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix() * input.globals[j].topLeftCorner<3, 3>();
  }
  Eigen::VectorXf frame;
  servable->engine->frame(input, frame);
  PointMatrix expected;
  animation_space::evaluate(*servable->animation_space, input.globals, expected);
  ASSERT_EQ(frame.size(), expected.size());
  EXPECT_EQ(frame, Eigen::Map<const Eigen::VectorXf>(expected.data(), expected.size()));

  const std::vector<int> some{0, 5, static_cast<int>(expected.rows()) - 1};
  Eigen::VectorXf points;
  servable->engine->points(input, some, points);
  ASSERT_EQ(points.size(), 9);
  for (size_t k = 0; k < some.size(); ++k) {
    EXPECT_EQ(points.segment(3 * static_cast<long>(k), 3), frame.segment(3 * some[k], 3)) << "point " << some[k];
  }
}

TEST(Engine, ACrossPmscModelHasNone) {
  auto container = demo::make_demo_cross_pmsc_container(24);
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto servable = load_servable(*container, "demo");
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  EXPECT_TRUE(servable->pmsc);
  EXPECT_FALSE(servable->engine);
}

}  // namespace
}  // namespace animspace::model
