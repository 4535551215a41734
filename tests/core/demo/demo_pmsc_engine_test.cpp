// The arm-pmsc-engine demo: a soft cache trained on the animation-space arm's own output, which
// it carries as its posing engine; and the PMSC demos keep their training options for retraining.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/demo/bending_arm.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "core/model/model_info.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/retrain.h"
#include "core/pmsc/train.h"

namespace animspace::demo {
namespace {

double arm_diagonal() {
  const ArmRig rig = make_arm_rig();
  return pmsc::bounding_box_diagonal(Eigen::Map<const Eigen::VectorXf>(rig.rest.V.data(), rig.rest.V.size()));
}

TEST(DemoPmscEngine, FramesAreTheEnginesOutputAtTheStoredPoses) {
  auto container = make_demo_pmsc_engine_container();
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto info = model::describe(*container, "arm-pmsc-engine");
  ASSERT_TRUE(info.ok()) << info.error().message;
  EXPECT_EQ(info->kind, container::ModelKind::kPmsc);
  EXPECT_EQ(info->fail_through, model::FailThrough::kServer);
  EXPECT_EQ(info->bone_count, 3);
  EXPECT_EQ(info->frame_count, kDemoFrames / 2);
  EXPECT_FALSE(info->description.empty());
  EXPECT_TRUE(pmsc::has_posing_engine(*container));
  EXPECT_TRUE(pmsc::load(*container, "arm-pmsc-engine").ok());
  EXPECT_TRUE(pmsc::load_training_options(*container, "arm-pmsc-engine").ok());

  auto engine = animation_space::load(*container, "arm-pmsc-engine");
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  auto levels = lod::load_levels(*container, *engine, "arm-pmsc-engine");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  EXPECT_EQ(levels->count(), 1);

  auto frames = container->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());
  auto bones = container->double_matrix(container::sections::kSequenceBoneTransforms, 48);
  ASSERT_TRUE(bones.ok()) << bones.error().message;
  ASSERT_EQ(bones->rows(), frames->rows());

  const ArmRig rig = make_arm_rig();
  const auto poses = demo_animation(kDemoFrames);
  const auto& P = engine->positions;
  for (Eigen::Index row = 0; row < frames->rows(); ++row) {
    // Row r holds even demo frame 2r: G_0 = I, then the rig's own bone transforms.
    const auto G = bone_transforms(poses[static_cast<size_t>(2 * row)], rig.options);
    const auto stored = animation_space::pose_from_row(*bones, row, 3);
    EXPECT_TRUE(stored[0].isIdentity(0)) << "row " << row;
    EXPECT_TRUE(stored[1].isApprox(G[kUpperArm], 1e-12)) << "row " << row;
    EXPECT_TRUE(stored[2].isApprox(G[kForearm], 1e-12)) << "row " << row;
    // v_i = Σ_j G_j p_j (Merry 2007 eq. 3.1), summed here by hand over the influences.
    float worst = 0;
    for (int i = 0; i < engine->vertex_count(); ++i) {
      Eigen::Vector4d v = Eigen::Vector4d::Zero();
      for (int k = engine->influences.begin(i); k < engine->influences.end(i); ++k) {
        v += stored[static_cast<size_t>(engine->influences.bones[static_cast<size_t>(k)])] * P.col(k);
      }
      for (int c = 0; c < 3; ++c) {
        worst = std::max(worst, std::abs((*frames)(row, 3 * i + c) - static_cast<float>(v(c))));
      }
    }
    EXPECT_LT(worst, 1e-6f * 4) << "row " << row;  // float rounding of coordinates ≲ 2
  }
}

TEST(DemoPmscEngine, PmscDemosStoreTheirTrainingOptions) {
  const double diagonal = arm_diagonal();
  auto arm_pmsc = make_demo_pmsc_container();
  ASSERT_TRUE(arm_pmsc.ok()) << arm_pmsc.error().message;
  auto options = pmsc::load_training_options(*arm_pmsc, "arm-pmsc");
  ASSERT_TRUE(options.ok()) << options.error().message;
  // The documented demo settings: bound 0.25%, tolerance 1% of the rest diagonal, 60 keys.
  EXPECT_NEAR(options->error_bound, 0.0025 * diagonal, 1e-12);
  EXPECT_NEAR(options->error_tolerance, 0.01 * diagonal, 1e-12);
  EXPECT_EQ(options->max_key_points, 60);
  auto info = model::describe(*arm_pmsc, "arm-pmsc");
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->fail_through, model::FailThrough::kClient);

  // And so it can be retrained as it stands.
  auto retrained = pmsc::retrain(*arm_pmsc, 1, FrameMatrix(), 0, {}, "arm-pmsc/1");
  ASSERT_TRUE(retrained.ok()) << retrained.error().message;
  EXPECT_EQ(retrained->training_frames, kDemoFrames / 2);
}

}  // namespace
}  // namespace animspace::demo
