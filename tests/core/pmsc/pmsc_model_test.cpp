#include "core/pmsc/pmsc_model.h"

#include <cmath>

#include <gtest/gtest.h>

#include "tests/support/pmsc_fixtures.h"

namespace animspace::pmsc {
namespace {

// The hand-worked three-point model (tests/support/pmsc_fixtures.h) with ε = [0.1, 0.2].
PmscModel three_point_model(std::vector<int> keys) { return testing::three_point_model(keys, {0.1, 0.2}); }

TEST(PmscModel, HandWorkedThreePointExample) {
  PmscModel m = three_point_model({0, 1});
  ASSERT_TRUE(prepare_projection(m).ok());
  // A_key = (1/3, 2/3): p = A_keyᵀ f / A_keyᵀA_key = (1/3 + 2/3) / (5/9) = 9/5 for f_key = (1, 1).
  Eigen::VectorXf keys(2);
  keys << 1, 1;
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  ASSERT_EQ(estimate.coordinates.size(), 1);
  EXPECT_NEAR(estimate.coordinates(0), 1.8, 1e-6);  // the basis is stored in float
  // f̂ = 1.8 · (1, 2, 2)/3 = (0.6, 1.2, 1.2); key residual (0.4, −0.2); e_key = √(0.2/2).
  EXPECT_NEAR(estimate.points(0), 0.6, 1e-6);
  EXPECT_NEAR(estimate.points(1), 1.2, 1e-6);
  EXPECT_NEAR(estimate.points(2), 1.2, 1e-6);
  EXPECT_NEAR(estimate.key_point_error, std::sqrt(0.1), 1e-7);
  EXPECT_DOUBLE_EQ(m.condition_number, 1.0);  // one singular value
}

TEST(PmscModel, PoseInTheSubspaceIsReconstructedExactlyFromOneKey) {
  PmscModel m = three_point_model({2});
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(1);
  keys << 0.5f * 2.0f / 3;  // the key value of the pose f = 0.5 a
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  EXPECT_NEAR(estimate.points(0), 0.5 / 3, 1e-7);
  EXPECT_NEAR(estimate.points(1), 1.0 / 3, 1e-7);
  EXPECT_NEAR(estimate.key_point_error, 0.0, 1e-7);
}

TEST(PmscModel, BatchEqualsOnePoseAtATime) {
  PmscModel m = three_point_model({0, 1});
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::MatrixXf keys(2, 4);
  keys << 1, 0, -2, 0.3f, 1, 3, 0.5f, 0.6f;
  Eigen::MatrixXf points;
  Eigen::VectorXd errors;
  evaluate_batch(m, keys, points, errors);
  ASSERT_EQ(points.cols(), 4);
  for (long b = 0; b < 4; ++b) {
    PoseEstimate one;
    evaluate(m, keys.col(b), one);
    EXPECT_TRUE(points.col(b).isApprox(one.points, 1e-6f)) << b;
    EXPECT_NEAR(errors(b), one.key_point_error, 1e-9) << b;
  }
}

TEST(PmscModel, TooFewKeyEquationsAreRefused) {
  PmscModel m = three_point_model({0});
  m.basis.conservativeResize(3, 2);
  m.basis.col(1) << 2.0f / 3, 1.0f / 3, -2.0f / 3;
  m.key_basis.conservativeResize(1, 2);
  m.key_basis(0, 1) = 2.0 / 3;
  auto status = prepare_projection(m);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(status.error().message.find("fewer equations"), std::string::npos);
}

TEST(PmscModel, IllConditionedKeysAreRegularisedNeverNaN) {
  // Two nearly parallel basis directions seen through two keys: σ_min/σ_max ≈ 1e-9.
  PmscModel m;
  m.channel_count = 1;
  m.point_count = 2;
  m.control_point_count = 2;
  m.mean = Eigen::VectorXf::Zero(2);
  m.basis.resize(2, 2);
  m.basis << 1, 1, 1, 1.000001f;
  m.key_points = {0, 1};
  m.key_mean = Eigen::VectorXd::Zero(2);
  m.key_basis.resize(2, 2);
  m.key_basis << 1, 1, 1, 1 + 1e-9;
  m.epsilon = {0.1, 0.2};
  ASSERT_TRUE(prepare_projection(m).ok());
  EXPECT_GT(m.condition_number, kMaxConditionNumber);
  EXPECT_GT(m.regularization, 0);
  EXPECT_TRUE(m.projection.allFinite());
  Eigen::VectorXf keys(2);
  keys << 1, -1;  // the direction the keys can hardly see
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  EXPECT_TRUE(estimate.points.allFinite());
  EXPECT_TRUE(std::isfinite(estimate.key_point_error));
  // Without regularisation p would be ~1e9; with it the answer stays bounded.
  EXPECT_LT(estimate.coordinates.cwiseAbs().maxCoeff(), 1e7);
}

// A key basis out of scale with the basis it indexes (a corrupt or hand-made file) would
// amplify ordinary key values into Inf points; it is refused at load, naming the member.
TEST(PmscModel, AKeyBasisOutOfScaleWithTheBasisIsRefused) {
  PmscModel m = three_point_model({0, 1});
  m.key_basis *= 1e-200;
  // σ(A_key) = 1e-200·√5/3, the only singular value, so ‖P‖ = 3e200/√5; with ‖A‖_F = 1 the
  // amplification is about 1.34e200.
  const Status status = prepare_projection(m);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(status.error().message.find("key_basis is out of scale with basis"), std::string::npos)
      << status.error().message;
  // The same model at a sane scale (amplification 3/√5 ≈ 1.34) loads.
  PmscModel sane = three_point_model({0, 1});
  EXPECT_TRUE(prepare_projection(sane).ok());
}

TEST(PmscModel, BadShapesNameTheMember) {
  PmscModel m = three_point_model({0, 1});
  m.key_mean.resize(5);
  auto status = prepare_projection(m);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("key_mean"), std::string::npos);

  PmscModel out_of_range = three_point_model({0, 3});
  status = prepare_projection(out_of_range);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("outside [0, 3)"), std::string::npos);
}

TEST(PmscModel, RegionErrorsSplitTheKeyResidual) {
  PmscModel m = three_point_model({0, 1});
  m.region_count = 2;
  m.point_regions = {0, 1, 1};
  m.key_regions = {0, 1};
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(2);
  keys << 1, 1;
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  ASSERT_EQ(estimate.region_errors.size(), 2u);
  EXPECT_NEAR(estimate.region_errors[0], 0.4, 1e-6);  // |1 − 0.6|
  EXPECT_NEAR(estimate.region_errors[1], 0.2, 1e-6);  // |1 − 1.2|
}

}  // namespace
}  // namespace animspace::pmsc

namespace animspace::pmsc {
namespace {

TEST(PmscModel, CachedEvaluationBlendsWithFullValuesOnlyOutsideTheHitZone) {
  PmscModel m = three_point_model({0, 1});
  m.epsilon = {0.2, 0.4};
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(2);
  keys << 1, 1;  // e_key = √0.1 ≈ 0.316: a blend with α = (0.316 − 0.2)/0.2
  const double alpha = (std::sqrt(0.1) - 0.2) / 0.2;
  Eigen::VectorXf full(3);
  full << 1, 1, 1;

  CachedPose without_full;
  evaluate_cached(m, keys, nullptr, without_full);
  EXPECT_EQ(without_full.status, CacheStatus::kBlend);
  EXPECT_NEAR(without_full.alpha, alpha, 1e-6);
  EXPECT_TRUE(without_full.full_evaluation_needed);
  EXPECT_NEAR(without_full.points(0), 0.6, 1e-6);  // the estimate

  CachedPose with_full;
  evaluate_cached(m, keys, &full, with_full);
  EXPECT_FALSE(with_full.full_evaluation_needed);
  // α f + (1 − α) f̂ at point 0: α·1 + (1 − α)·0.6.
  EXPECT_NEAR(with_full.points(0), alpha + (1 - alpha) * 0.6, 1e-6);
  EXPECT_NEAR(with_full.key_point_error, std::sqrt(0.1), 1e-7);

  // A miss takes the full values themselves (eq. 9): keys (10, −10) give p = −6 and
  // e_key = √90 ≈ 9.5 ≥ ε_max.
  Eigen::VectorXf far(2);
  far << 10, -10;
  Eigen::VectorXf exact(3);
  exact << 0.25f, -1e30f, 7.0f;
  CachedPose missed;
  evaluate_cached(m, far, &exact, missed);
  EXPECT_EQ(missed.status, CacheStatus::kMiss);
  EXPECT_EQ(missed.points, exact);

  // A cross-PMSC model never asks for a full calculation.
  m.cross = true;
  CachedPose cross;
  evaluate_cached(m, keys, nullptr, cross);
  EXPECT_EQ(cross.status, CacheStatus::kBlend);
  EXPECT_FALSE(cross.full_evaluation_needed);
}

// Fail-through (2007 §2.4 step 5): the engine runs only for a blend or a miss without full values
// from the caller, and its f is used exactly as values the caller sent would be.
TEST(PmscModel, FailThroughRunsTheFullCalculationOnlyWhenTheSoftCacheCannotAnswer) {
  PmscModel m = three_point_model({0, 1});
  m.epsilon = {0.2, 0.4};
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf full(3);
  full << 1, 1, 1;
  int calls = 0;
  const FullCalculation engine = [&](Eigen::VectorXf& f) {
    ++calls;
    f = full;
    return true;
  };

  Eigen::VectorXf blend_keys(2);
  blend_keys << 1, 1;  // a blend (see the test above)
  CachedPose from_engine, from_caller;
  evaluate_cached(m, blend_keys, nullptr, engine, from_engine);
  evaluate_cached(m, blend_keys, &full, from_caller);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(from_engine.status, CacheStatus::kBlend);
  EXPECT_FALSE(from_engine.full_evaluation_needed);
  EXPECT_EQ(from_engine.points, from_caller.points);
  EXPECT_EQ(from_engine.computed_full_values, full);

  // Values the caller sent win: the engine is not run.
  CachedPose caller_wins;
  evaluate_cached(m, blend_keys, &full, engine, caller_wins);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(caller_wins.computed_full_values.size(), 0);

  // A miss returns f itself (eq. 9).
  Eigen::VectorXf far(2);
  far << 10, -10;
  CachedPose missed;
  evaluate_cached(m, far, nullptr, engine, missed);
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(missed.status, CacheStatus::kMiss);
  EXPECT_EQ(missed.points, full);

  // A hit never runs it: keys on the subspace, p = 3 · (1/3, 2/3) = (1, 2), have e_key 0.
  Eigen::VectorXf on_subspace(2);
  on_subspace << 1, 2;
  CachedPose hit;
  evaluate_cached(m, on_subspace, nullptr, engine, hit);
  EXPECT_EQ(hit.status, CacheStatus::kHit);
  EXPECT_EQ(calls, 2);

  // An engine that cannot pose this pose leaves the estimate and asks for f.
  const FullCalculation refuses = [](Eigen::VectorXf&) { return false; };
  CachedPose unanswered;
  evaluate_cached(m, blend_keys, nullptr, refuses, unanswered);
  EXPECT_TRUE(unanswered.full_evaluation_needed);
  EXPECT_NEAR(unanswered.points(0), 0.6, 1e-6);
}

TEST(PmscModel, FullValuesMustRepeatTheKeyValuesUpToTheStatedTolerance) {
  PmscModel m = three_point_model({2, 0});  // ε_min = 0.1: an absolute allowance of 1e-4
  Eigen::VectorXf keys(2);
  keys << 4, -1;
  Eigen::VectorXf full(3);
  full << -1, 7, 4;
  EXPECT_TRUE(check_full_values_at_keys(m, keys, full).ok());
  // Within 1e-5·4 + 1e-4 = 1.4e-4 of key 0 (point 2): accepted; beyond: refused, named.
  full(2) = 4 + 1.3e-4f;
  EXPECT_TRUE(check_full_values_at_keys(m, keys, full).ok());
  full(2) = 4 + 1.6e-4f;
  auto refused = check_full_values_at_keys(m, keys, full);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("key point 0 (point 2): the full values hold (4.00016) but the key values "
                                         "hold (4)"),
            std::string::npos)
      << refused.error().message;
  // The second key (point 0) differs by 1: the first mismatch in key order is the one named.
  full << 0, 7, 4;
  refused = check_full_values_at_keys(m, keys, full);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("key point 1 (point 0)"), std::string::npos) << refused.error().message;
  // NaN never passes.
  full << std::nanf(""), 7, 4;
  EXPECT_FALSE(check_full_values_at_keys(m, keys, full).ok());
}

TEST(PmscModel, HitRateCountsTheFramesTheSoftCacheAnswersAlone) {
  PmscModel m = three_point_model({0, 1});
  ASSERT_TRUE(prepare_projection(m).ok());
  // Frames in the subspace (e_key = 0: hits) and one whose keys (1, 1) leave it: e_key = √0.1 ≈
  // 0.32 > ε_max = 0.2 (the hand-worked example above), a miss.
  FrameMatrix frames(4, 3);
  frames << 1, 2, 2,  //
      0.5f, 1, 1,     //
      1, 1, 0,        //
      -3, -6, -6;
  EXPECT_DOUBLE_EQ(hit_rate(m, frames), 0.75);
  EXPECT_DOUBLE_EQ(hit_rate(m, FrameMatrix(0, 3)), 0.0);
}

}  // namespace
}  // namespace animspace::pmsc
