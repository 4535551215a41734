// The demo's animation-space model, judged on the frames it was not fitted to.
#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/demo/bending_arm.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "core/model/model_info.h"

namespace animspace::demo {
namespace {

double rms_distance(const PointMatrix& a, const PointMatrix& b) {
  return std::sqrt((a - b).cast<double>().rowwise().squaredNorm().mean());
}

TEST(DemoAnimationSpaceTest, BeatsLinearBlendSkinningOnUnseenFrames) {
  auto container = make_demo_animation_space_container();
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto info = model::describe(*container, "demo");
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, container::ModelKind::kAnimationSpace);
  EXPECT_EQ(info->bone_count, 3);
  auto model = animation_space::load(*container, "demo");
  ASSERT_TRUE(model.ok()) << model.error().message;

  // Odd frames were not fitted. The reference is the expensive rig itself; the baseline is the
  // rig's own LBS (its hand-made weights) on the same poses.
  const ArmRig rig = make_arm_rig();
  const auto poses = demo_animation(kDemoFrames);
  double animation_space_error = 0, linear_blend_error = 0;
  PointMatrix posed;
  for (int f = 1; f < kDemoFrames; f += 2) {
    const ArmPose& pose = poses[static_cast<size_t>(f)];
    const PointMatrix expected = pose_expensive(pose, rig);
    const auto G = bone_transforms(pose, rig.options);
    animation_space::evaluate(*model, {animation_space::Transform::Identity(), G[kUpperArm], G[kForearm]}, posed);
    animation_space_error = std::max(animation_space_error, rms_distance(posed, expected));
    linear_blend_error = std::max(linear_blend_error, rms_distance(pose_linear_blend(pose, rig), expected));
  }
  EXPECT_LT(animation_space_error, 0.5 * linear_blend_error)
      << "animation space " << animation_space_error << " vs LBS " << linear_blend_error;
}

TEST(DemoAnimationSpaceTest, CarriesLevelsOfDetail) {
  auto container = make_demo_animation_space_container();
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto info = model::describe(*container, "demo");
  ASSERT_TRUE(info.ok());
  auto model = animation_space::load(*container, "demo");
  ASSERT_TRUE(model.ok());
  auto levels = lod::load_levels(*container, *model, "demo");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  EXPECT_GE(levels->count(), 4);
  EXPECT_EQ(info->lod_level_count, levels->count());
  // Levels are cut where the edge collapses halve the influences (§7.3), and then each level's
  // influences are simplified after placement (lod/levels.h): every level has fewer vertices and
  // fewer influences than the one before.
  for (int l = 1; l < levels->count(); ++l) {
    const auto& level = levels->levels[static_cast<size_t>(l)].model;
    const auto& finer = levels->levels[static_cast<size_t>(l) - 1].model;
    EXPECT_LT(level.vertex_count(), finer.vertex_count()) << "level " << l;
    EXPECT_LT(level.influences.influence_count(), finer.influences.influence_count()) << "level " << l;
  }
}

}  // namespace
}  // namespace animspace::demo
