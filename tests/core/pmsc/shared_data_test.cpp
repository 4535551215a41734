// PMSC on a real captured sequence (../shared/data/horse-gallop); skipped when the data is absent.
// The full measurements are the `animspace-bench pmsc` suite; this guards the behaviour.
#include <gtest/gtest.h>

#include "core/mesh_io/sequence_io.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/train.h"
#include "tests/support/test_support.h"

namespace animspace::pmsc {
namespace {

TEST(PmscSharedData, HorseGallopSoftCacheFlagsEveryPoorEstimate) {
  const auto data = testing::shared_data_dir();
  if (!data) GTEST_SKIP() << "../shared/data is absent";
  auto sequence = mesh_io::load_sequence(*data / "horse-gallop");
  ASSERT_TRUE(sequence.ok()) << sequence.error().message;
  const FrameMatrix& all = sequence->frames.samples;
  const Eigen::VectorXf reference =
      Eigen::Map<const Eigen::VectorXf>(sequence->reference.V.data(), sequence->reference.V.size());
  const double diagonal = bounding_box_diagonal(reference);

  // Train on the even frames; the odd ones are the test set.
  FrameMatrix train_frames((all.rows() + 1) / 2, all.cols());
  for (long f = 0; f < all.rows(); f += 2) train_frames.row(f / 2) = all.row(f);
  TrainingOptions options;
  options.error_bound = 0.0025 * diagonal;
  options.error_tolerance = 0.01 * diagonal;
  TrainingReport report;
  auto model = train(train_frames, options, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_LT(model->basis_size(), train_frames.rows());

  for (long f = 0; f < all.rows(); ++f) {
    const Eigen::VectorXf truth = all.row(f).transpose();
    CachedPose answer;  // posed from its key and check points, as a client sends them
    evaluate_cached(*model, gather_key_values(*model, truth), gather_check_values(*model, truth), nullptr,
                    FullCalculation(), answer);
    const double error = max_point_error((truth - answer.points).cast<double>(), 3);
    const bool flagged = answer.status != CacheStatus::kHit;
    if (f % 2 == 0) {
      EXPECT_LT(error, 0.01 * diagonal) << "training frame " << f;  // reproduced within tolerance
    } else if (error > 0.01 * diagonal) {
      EXPECT_TRUE(flagged) << "test frame " << f << " is " << 100 * error / diagonal << "% off but a hit";
    }
  }
}

}  // namespace
}  // namespace animspace::pmsc
