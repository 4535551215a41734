// The served subspace (core/pmsc/subspace.h): estimate, reconstruct and finish on hand-worked
// poses — the answer as points or as coordinates, the engine called only when the soft cache
// cannot answer alone, each region's verdict by the rule local fail-through acts on — and the
// registry that gives each kind its runtime.
#include "core/pmsc/subspace.h"

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/pmsc_fixtures.h"

namespace animspace::pmsc {
namespace {

// three_point_model (tests/support): a = (1, 2, 2)/3, keys {0, 1}, ε = [0.1, 0.5]. Key values
// (1, 1) give f̂ = (0.6, 1.2, 1.2), e_key = √0.1 (a blend with α = (√0.1 − 0.1)/0.4); keys
// (0.5, 1) lie on the subspace (a hit).
std::shared_ptr<const Subspace> three_point_subspace(int region_count) {
  PmscModel m = testing::three_point_model({0, 1}, {0.1, 0.5});
  if (region_count == 2) {
    m.region_count = 2;
    m.point_regions = {0, 1, 1};
    m.key_regions = {0, 1};
    // Region 0's error |1 − 0.6| = 0.4 blends; region 1's |1 − 1.2| = 0.2 is under its 0.3.
    m.region_epsilon = {{0.1, 0.5}, {0.3, 0.5}};
  }
  EXPECT_TRUE(prepare_projection(m).ok());
  auto subspace = make_subspace(std::make_shared<const PmscModel>(std::move(m)));
  EXPECT_TRUE(subspace.ok());
  return *subspace;
}

Eigen::VectorXf vector_of(std::initializer_list<float> values) {
  Eigen::VectorXf v(static_cast<long>(values.size()));
  long i = 0;
  for (float x : values) v(i++) = x;
  return v;
}

const double kBlendAlpha = (std::sqrt(0.1) - 0.1) / 0.4;

TEST(Subspace, AnAnswerAsPointsIsBlendedInPlaceWithTheFullValues) {
  const auto subspace = three_point_subspace(0);
  PoseEstimate estimate;
  subspace->estimate(vector_of({1, 1}), Eigen::VectorXf(), estimate);
  EXPECT_NEAR(estimate.key_point_error, std::sqrt(0.1), 1e-6);
  EXPECT_NEAR(estimate.key_point_max_error, 0.4, 1e-6);  // the worst key: |1 − 0.6| against |1 − 1.2|
  Eigen::VectorXf points(3);
  const PoseEstimate* input = &estimate;
  float* destination = points.data();
  subspace->reconstruct({&input, 1}, {&destination, 1});
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(points(i), (i == 0 ? 0.6 : 1.2), 1e-6) << i;

  const Eigen::VectorXf full = vector_of({1, 1, 2});
  FinishInput finish;
  finish.points = points.data();
  finish.full_values = &full;
  PoseAnswer answer;
  ASSERT_TRUE(subspace->finish(estimate, finish, answer).ok());
  EXPECT_EQ(answer.cached.status, CacheStatus::kBlend);
  EXPECT_NEAR(answer.cached.alpha, kBlendAlpha, 1e-7);
  EXPECT_EQ(answer.points, points.data()) << "the answer is written over f̂, not copied";
  const double f_hat[] = {0.6, 1.2, 1.2};
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(points(i), kBlendAlpha * full(i) + (1 - kBlendAlpha) * f_hat[i], 1e-6) << i;  // eq. 11
  }
  EXPECT_FALSE(answer.cached.full_evaluation_needed);
  EXPECT_TRUE(answer.region_statuses.empty());
}

TEST(Subspace, AnAnswerAsCoordinatesIsReconstructedOnlyWhenTheFullValuesAreAtHand) {
  const auto subspace = three_point_subspace(0);
  int engine_calls = 0;
  const FullCalculation engine = [&](Eigen::VectorXf& full) {
    ++engine_calls;
    full = vector_of({1, 1, 2});
    return true;
  };

  // A blend without f: the coordinates, and the client is told to compute f.
  PoseEstimate estimate;
  subspace->estimate(vector_of({1, 1}), Eigen::VectorXf(), estimate);
  PoseAnswer answer;
  ASSERT_TRUE(subspace->finish(estimate, FinishInput{}, answer).ok());
  EXPECT_EQ(answer.points, nullptr);
  EXPECT_EQ(answer.cached.status, CacheStatus::kBlend);
  EXPECT_TRUE(answer.cached.full_evaluation_needed);

  // The same blend with an engine: the server answers with the blended points itself.
  FinishInput with_engine;
  with_engine.full_calculation = engine;
  ASSERT_TRUE(subspace->finish(estimate, with_engine, answer).ok());
  ASSERT_NE(answer.points, nullptr);
  EXPECT_EQ(engine_calls, 1);
  EXPECT_NEAR(answer.points[2], kBlendAlpha * 2 + (1 - kBlendAlpha) * 1.2, 1e-6);
  EXPECT_EQ(answer.cached.computed_full_values, vector_of({1, 1, 2})) << "the example a miss log keeps";
  EXPECT_FALSE(answer.cached.full_evaluation_needed);

  // A hit never asks the engine and stays coordinates.
  subspace->estimate(vector_of({0.5f, 1}), Eigen::VectorXf(), estimate);
  ASSERT_TRUE(subspace->finish(estimate, with_engine, answer).ok());
  EXPECT_EQ(answer.cached.status, CacheStatus::kHit);
  EXPECT_EQ(answer.points, nullptr);
  EXPECT_FALSE(answer.cached.full_evaluation_needed);
  EXPECT_EQ(engine_calls, 1);
}

TEST(Subspace, LocalFailThroughComputesOnlyTheRegionThatFails) {
  const auto subspace = three_point_subspace(2);
  PoseEstimate estimate;
  subspace->estimate(vector_of({1, 1}), Eigen::VectorXf(), estimate);
  Eigen::VectorXf points(3);
  const PoseEstimate* input = &estimate;
  float* destination = points.data();
  subspace->reconstruct({&input, 1}, {&destination, 1});
  std::vector<std::vector<int>> asked;
  FinishInput finish;
  finish.points = points.data();
  finish.local = true;
  finish.partial_calculation = [&](const std::vector<int>& wanted, Eigen::VectorXf& values) {
    asked.push_back(wanted);
    values = Eigen::VectorXf::Constant(static_cast<long>(wanted.size()), 3.0f);
    return true;
  };
  PoseAnswer answer;
  ASSERT_TRUE(subspace->finish(estimate, finish, answer).ok());
  // Region 0 blends with α = (0.4 − 0.1)/0.4 = 0.75 and only its point is computed.
  ASSERT_EQ(asked, (std::vector<std::vector<int>>{{0}}));
  ASSERT_EQ(answer.local.full_points, (std::vector<int>{0}));
  EXPECT_NEAR(points(0), 0.75 * 3.0 + 0.25 * 0.6, 1e-6);
  EXPECT_NEAR(points(1), 1.2, 1e-6);
  EXPECT_EQ(answer.region_statuses, (std::vector<CacheStatus>{CacheStatus::kBlend, CacheStatus::kHit}));

  // Partial full values that miss point 0 are refused, naming it.
  Eigen::VectorXf given_values = Eigen::VectorXf::Constant(1, 3.0f);
  const std::vector<int> given_points = {2};
  subspace->reconstruct({&input, 1}, {&destination, 1});
  finish.full_values = &given_values;
  finish.full_points = &given_points;
  const Status refused = subspace->finish(estimate, finish, answer);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("point 0 needs the full calculation"), std::string::npos)
      << refused.error().message;
}

// Regions calibrated for estimates that include check points judge only such estimates: a pose
// sent without its check values gets the whole pose's verdict in every region.
TEST(Subspace, RegionsTakeTheWholeVerdictWhenTheirCalibrationDoesNotApply) {
  PmscModel m = testing::three_point_model({0, 1}, {0.1, 0.5});
  m.region_count = 2;
  m.point_regions = {0, 1, 1};
  m.key_regions = {0, 1};
  m.region_epsilon = {{0.1, 0.5}, {0.3, 0.5}};
  m.check_points = {2};
  m.check_regions = {1};
  m.key_only_epsilon = {0.1, 0.5};
  ASSERT_TRUE(prepare_projection(m).ok());
  auto subspace = make_subspace(std::make_shared<const PmscModel>(std::move(m)));
  ASSERT_TRUE(subspace.ok());
  PoseEstimate estimate;
  (*subspace)->estimate(vector_of({1, 1}), Eigen::VectorXf(), estimate);
  PoseAnswer answer;
  ASSERT_TRUE((*subspace)->finish(estimate, FinishInput{}, answer).ok());
  ASSERT_EQ(answer.cached.status, CacheStatus::kBlend);
  EXPECT_EQ(answer.region_statuses, (std::vector<CacheStatus>{CacheStatus::kBlend, CacheStatus::kBlend}));
  // With the check value f̂_2 = 1.2 itself, e_check = 0 and the regions are judged alone.
  (*subspace)->estimate(vector_of({1, 1}), vector_of({1.2f}), estimate);
  ASSERT_TRUE((*subspace)->finish(estimate, FinishInput{}, answer).ok());
  ASSERT_TRUE(answer.cached.checked);
  EXPECT_EQ(answer.region_statuses, (std::vector<CacheStatus>{CacheStatus::kBlend, CacheStatus::kHit}));
}

// The linear kind's runtime is the dense product itself; a kind the registry does not know is
// refused by name rather than served by the wrong runtime.
TEST(Subspace, EachKindGetsItsRuntime) {
  std::mt19937 random(51);
  PmscModel m = testing::random_model(random, 40, 4, 8, false);
  auto linear = make_subspace(std::make_shared<const PmscModel>(m));
  ASSERT_TRUE(linear.ok());
  PoseEstimate estimate;
  (*linear)->estimate(testing::random_keys(random, m), Eigen::VectorXf(), estimate);
  Eigen::VectorXf served(m.mean.size()), dense(m.mean.size());
  const PoseEstimate* input = &estimate;
  float* destination = served.data();
  (*linear)->reconstruct({&input, 1}, {&destination, 1});
  destination = dense.data();
  reconstruct(m, {&input, 1}, {&destination, 1});
  EXPECT_EQ(served, dense);

  m.subspace_kind = static_cast<SubspaceKind>(7);
  const auto unknown = make_subspace(std::make_shared<const PmscModel>(m));
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("unknown subspace kind 7"), std::string::npos) << unknown.error().message;
}

}  // namespace
}  // namespace animspace::pmsc
