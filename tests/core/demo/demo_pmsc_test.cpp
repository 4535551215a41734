// The PMSC demo models behave as the soft cache promises on the arm: held-out frames of the
// animation are hits within tolerance, a pose far outside the training range is flagged.
#include <gtest/gtest.h>

#include "core/demo/bending_arm.h"
#include "core/demo/demo_repository.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/train.h"

namespace animspace::demo {
namespace {

Eigen::VectorXf as_frame(const PointMatrix& P) { return Eigen::Map<const Eigen::VectorXf>(P.data(), P.size()); }

TEST(DemoPmsc, HeldOutFramesAreHitsAndANovelPoseIsFlagged) {
  auto container = make_demo_pmsc_container();
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto model = pmsc::load(*container, "arm-pmsc");
  ASSERT_TRUE(model.ok()) << model.error().message;
  const ArmRig rig = make_arm_rig();
  const double diagonal = pmsc::bounding_box_diagonal(as_frame(rig.rest.V));
  const auto poses = demo_animation(kDemoFrames);

  // A client sends the key and the check points of each pose.
  const auto answer = [&](const Eigen::VectorXf& truth) {
    pmsc::CachedPose out;
    pmsc::evaluate_cached(*model, pmsc::gather_key_values(*model, truth), pmsc::gather_check_values(*model, truth),
                          nullptr, pmsc::FullCalculation(), out);
    return out;
  };
  EXPECT_GT(model->check_point_count(), 0);
  int hits = 0, held_out = 0;
  for (size_t f = 1; f < poses.size(); f += 2) {  // trained on the even frames
    const Eigen::VectorXf truth = as_frame(pose_expensive(poses[f], rig));
    const pmsc::CachedPose cached = answer(truth);
    const Eigen::MatrixXd residual = (truth - cached.points).cast<double>();
    EXPECT_LT(pmsc::max_point_error(residual, 3), 0.01 * diagonal) << "frame " << f;
    hits += cached.status == pmsc::CacheStatus::kHit ? 1 : 0;
    ++held_out;
  }
  EXPECT_GT(hits, held_out * 9 / 10);

  // Elbow bent to 175° and twisted hard: never seen in training.
  const ArmPose novel{175.0 * M_PI / 180, 0.9, 1.2};
  const Eigen::VectorXf truth = as_frame(pose_expensive(novel, rig));
  const pmsc::CachedPose cached = answer(truth);
  const Eigen::MatrixXd residual = (truth - cached.points).cast<double>();
  ASSERT_GT(pmsc::max_point_error(residual, 3), 0.01 * diagonal) << "the novel pose should be outside the subspace";
  EXPECT_NE(cached.status, pmsc::CacheStatus::kHit);
}

TEST(DemoPmsc, CrossModelTurnsLinearBlendKeysIntoTheExpensiveRig) {
  auto container = make_demo_cross_pmsc_container();
  ASSERT_TRUE(container.ok()) << container.error().message;
  auto model = pmsc::load(*container, "arm-cross-pmsc");
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_TRUE(model->cross);
  const ArmRig rig = make_arm_rig();
  const double diagonal = pmsc::bounding_box_diagonal(as_frame(rig.rest.V));
  const auto poses = demo_animation(kDemoFrames);
  pmsc::PoseEstimate estimate;
  double worst_cross = 0, worst_lbs = 0;
  for (size_t f = 1; f < poses.size(); f += 2) {
    const Eigen::VectorXf control = as_frame(pose_linear_blend(poses[f], rig));
    const Eigen::VectorXf truth = as_frame(pose_expensive(poses[f], rig));
    pmsc::evaluate(*model, pmsc::gather_key_values(*model, control), estimate);
    worst_cross = std::max(worst_cross, pmsc::max_point_error((truth - estimate.points).cast<double>(), 3));
    worst_lbs = std::max(worst_lbs, pmsc::max_point_error((truth - control).cast<double>(), 3));
  }
  // The cheap rig alone misses the bulge; driven through the cross model it is recovered.
  EXPECT_LT(worst_cross, 0.01 * diagonal);
  EXPECT_GT(worst_lbs, 3 * worst_cross);
}

}  // namespace
}  // namespace animspace::demo
