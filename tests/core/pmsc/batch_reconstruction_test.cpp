// Dynamic batching (issue #25) rests on this: a pose reconstructed in a batch is the pose
// reconstructed alone, up to the stated float rounding, and its verdict is exactly the same.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/kernels.h"
#include "core/pmsc/pmsc_model.h"
#include "tests/support/pmsc_fixtures.h"

namespace animspace::pmsc {
namespace {

class BatchReconstructionTest : public ::testing::TestWithParam<Kernel> {
 protected:
  void SetUp() override { use_kernel(GetParam()); }
  void TearDown() override { use_kernel(saved_); }
  Kernel saved_ = active_kernel();
};

using testing::random_keys;

PmscModel random_model(std::mt19937& random, int points, int basis_size, int keys, bool aligned) {
  PmscModel m = testing::random_model(random, points, basis_size, keys, aligned);
  EXPECT_GT(m.projection.size(), 0) << "the random model did not prepare";
  return m;
}

void check_batches(const PmscModel& m, std::mt19937& random) {
  for (int batch : {1, 2, 3, 4, 5, 17, 64}) {
    std::vector<PoseEstimate> estimates(static_cast<size_t>(batch));
    std::vector<const PoseEstimate*> inputs;
    std::vector<Eigen::VectorXf> outputs(static_cast<size_t>(batch), Eigen::VectorXf(m.mean.size()));
    std::vector<float*> destinations;
    for (int b = 0; b < batch; ++b) {
      estimate_coordinates(m, random_keys(random, m), estimates[static_cast<size_t>(b)]);
      inputs.push_back(&estimates[static_cast<size_t>(b)]);
      destinations.push_back(outputs[static_cast<size_t>(b)].data());
    }
    reconstruct(m, inputs, destinations);
    const double bound = reconstruction_rounding_bound(m.basis_size());
    for (int b = 0; b < batch; ++b) {
      const PoseEstimate& e = estimates[static_cast<size_t>(b)];
      Eigen::VectorXf alone(m.mean.size());
      const PoseEstimate* one = &e;
      float* to = alone.data();
      reconstruct(m, {&one, 1}, {&to, 1});
      // The size of each value's sum, in double, independently of both paths.
      const Eigen::VectorXd tolerance = testing::reconstruction_tolerance(m, e.coordinates);
      const Eigen::VectorXf& batched = outputs[static_cast<size_t>(b)];
      if (!m.aligned) {
        const Eigen::VectorXf p = e.coordinates.cast<float>();
        const Eigen::VectorXd exact = m.mean.cast<double>() + m.basis.cast<double>() * p.cast<double>();
        for (long i = 0; i < exact.size(); ++i) {
          ASSERT_LE(std::abs(batched(i) - exact(i)), tolerance(i)) << "batch " << batch << " value " << i;
          ASSERT_LE(std::abs(batched(i) - alone(i)), tolerance(i)) << "batch " << batch << " value " << i;
        }
      } else {
        // The rotation moves each point's rounding error without growing it (plus its own rounding).
        for (long i = 0; i < m.point_count; ++i) {
          const double allowed = (1 + 1e-6 / bound) * tolerance.segment(3 * i, 3).norm();
          ASSERT_LE((batched.segment(3 * i, 3) - alone.segment(3 * i, 3)).norm(), allowed) << "point " << i;
        }
      }
    }
  }
}

TEST_P(BatchReconstructionTest, ABatchedPoseIsTheOnePoseAnswerWithinRounding) {
  std::mt19937 random(11);
  check_batches(random_model(random, 700, 9, 20, false), random);
}

TEST_P(BatchReconstructionTest, AlignedModelsToo) {
  std::mt19937 random(12);
  check_batches(random_model(random, 400, 6, 15, true), random);
}

TEST_P(BatchReconstructionTest, EvaluateBatchGivesEachPoseTheOnePoseVerdict) {
  std::mt19937 random(13);
  const PmscModel m = random_model(random, 300, 7, 12, false);
  Eigen::MatrixXf keys(m.key_mean.size(), 40);
  for (long b = 0; b < keys.cols(); ++b) keys.col(b) = random_keys(random, m);
  Eigen::MatrixXf points;
  Eigen::VectorXd errors;
  evaluate_batch(m, keys, points, errors);
  int hits = 0, misses = 0;
  for (long b = 0; b < keys.cols(); ++b) {
    CachedPose one;
    evaluate_cached(m, keys.col(b), nullptr, one);
    EXPECT_EQ(errors(b), one.key_point_error) << b;  // bit for bit: the same per-pose computation
    EXPECT_EQ(decide(errors(b), m.epsilon).status, one.status) << b;
    hits += one.status == CacheStatus::kHit;
    misses += one.status == CacheStatus::kMiss;
  }
  EXPECT_GT(hits, 0);  // the noise spans the thresholds, so both sides are exercised
  EXPECT_GT(misses, 0);
}

TEST_P(BatchReconstructionTest, FinishCachedOnAReconstructedPoseIsEvaluateCached) {
  std::mt19937 random(14);
  const PmscModel m = random_model(random, 200, 5, 10, false);
  for (int i = 0; i < 30; ++i) {
    const Eigen::VectorXf keys = random_keys(random, m);
    const Eigen::VectorXf full = m.mean + Eigen::VectorXf::Constant(m.mean.size(), 0.01f * static_cast<float>(i));
    CachedPose expected;
    evaluate_cached(m, keys, &full, expected);
    PoseEstimate estimate;
    estimate_coordinates(m, keys, estimate);
    Eigen::VectorXf points(m.mean.size());
    const PoseEstimate* in = &estimate;
    float* to = points.data();
    reconstruct(m, {&in, 1}, {&to, 1});
    CachedPose finished;
    finish_cached(m, estimate, points, &full, FullCalculation(), finished);
    EXPECT_EQ(finished.status, expected.status);
    EXPECT_EQ(finished.alpha, expected.alpha);
    EXPECT_EQ(points, expected.points);
  }
}

INSTANTIATE_TEST_SUITE_P(Kernels, BatchReconstructionTest, ::testing::Values(Kernel::kPortable, Kernel::kBlas),
                         [](const ::testing::TestParamInfo<Kernel>& parameter) {
                           return parameter.param == Kernel::kBlas ? std::string("Blas") : std::string("Portable");
                         });

// A forced-baseline run and the dispatched one agree on every verdict.
TEST(KernelDispatch, ThePortableKernelGivesTheDispatchedKernelsVerdicts) {
  const Kernel saved = active_kernel();
  std::mt19937 random(15);
  const PmscModel m = random_model(random, 300, 7, 12, false);
  for (int i = 0; i < 200; ++i) {
    const Eigen::VectorXf keys = random_keys(random, m);
    PoseEstimate portable, blas;
    use_kernel(Kernel::kPortable);
    estimate_coordinates(m, keys, portable);
    use_kernel(Kernel::kBlas);
    estimate_coordinates(m, keys, blas);
    EXPECT_NEAR(portable.key_point_error, blas.key_point_error, 1e-12 * (1 + blas.key_point_error));
    EXPECT_EQ(decide(portable.key_point_error, m.epsilon).status, decide(blas.key_point_error, m.epsilon).status);
  }
  use_kernel(saved);
}

}  // namespace
}  // namespace animspace::pmsc
