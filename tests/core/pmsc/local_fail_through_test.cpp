// Local fail-through (core/pmsc/local_fail_through.h): per-point blend weights from region
// verdicts, their smoothness across region borders, the partial blend, the completion of a
// partial frame, and the soft memberships' round trip through the container.
#include "core/pmsc/local_fail_through.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/regions.h"
#include "core/pmsc/train.h"
#include "tests/support/pmsc_fixtures.h"

namespace animspace::pmsc {
namespace {

// Four points of one channel in two regions, with soft memberships written by hand.
PmscModel four_point_regions() {
  PmscModel m;
  m.channel_count = 1;
  m.point_count = 4;
  m.control_point_count = 4;
  m.region_count = 2;
  m.point_regions = {0, 0, 1, 1};
  m.region_weights.resize(4, 2);
  m.region_weights << 1, 0, 0.75, 0.25, 0.25, 0.75, 0, 1;
  m.epsilon = {0.1, 0.3};
  return m;
}

TEST(LocalFailThrough, PointWeightsAreMembershipWeightedRegionVerdicts) {
  PmscModel m = four_point_regions();
  // Region 0: e = 0.2 in [0.1, 0.3] → α₀ = 0.5; region 1: e = 0.1 ≤ ε_min → hit, α₁ = 0.
  LocalFailThrough local = local_fail_through(m, 0.2, {0.2, 0.1});
  EXPECT_EQ(local.full_points, (std::vector<int>{0, 1, 2}));
  ASSERT_EQ(local.full_point_blend_weights.size(), 3u);
  EXPECT_DOUBLE_EQ(local.full_point_blend_weights[0], 0.5);
  EXPECT_DOUBLE_EQ(local.full_point_blend_weights[1], 0.75 * 0.5);
  EXPECT_DOUBLE_EQ(local.full_point_blend_weights[2], 0.25 * 0.5);

  // Each region is judged by its own thresholds when the model has them: e₁ = 0.25 against
  // [0.2, 0.4] is α₁ = 0.25 (against the model's [0.1, 0.3] it would be 0.75).
  m.region_epsilon = {{0.1, 0.3}, {0.2, 0.4}};
  local = local_fail_through(m, 0.2, {0.2, 0.25});
  EXPECT_EQ(local.full_points, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_NEAR(local.full_point_blend_weights[1], 0.75 * 0.5 + 0.25 * 0.25, 1e-12);
  EXPECT_NEAR(local.full_point_blend_weights[3], 0.25, 1e-12);

  // A miss region makes its deep points exactly 1 (eq. 9), and old (hard) models follow regions.
  local = local_fail_through(m, 1.0, {1.0, 0.0});
  EXPECT_EQ(local.full_point_blend_weights[0], 1.0);
  m.region_weights.resize(0, 0);
  local = local_fail_through(m, 1.0, {1.0, 0.0});
  EXPECT_EQ(local.full_points, (std::vector<int>{0, 1}));
  EXPECT_EQ(local.full_point_blend_weights, (std::vector<double>{1.0, 1.0}));

  // Cross-PMSC: no full calculation exists, nothing is asked for.
  m.cross = true;
  EXPECT_TRUE(local_fail_through(m, 1.0, {1.0, 1.0}).full_points.empty());
}

TEST(LocalFailThrough, WithoutRegionsEveryPointTakesTheWholePoseWeight) {
  PmscModel m = four_point_regions();
  m.region_count = 0;
  m.point_regions.clear();
  m.region_weights.resize(0, 0);
  LocalFailThrough local = local_fail_through(m, 0.25, {});
  EXPECT_EQ(local.full_points, (std::vector<int>{0, 1, 2, 3}));
  for (double alpha : local.full_point_blend_weights) EXPECT_DOUBLE_EQ(alpha, 0.75);
  EXPECT_TRUE(local_fail_through(m, 0.05, {}).full_points.empty());
}

// Three points, one channel, a one-vector subspace a = (1, 2, 2)/3, keys at points 0 and 1 (as
// pmsc_model_test's hand-worked example): f_key = (1, 1) gives f̂ = (0.6, 1.2, 1.2), e_key = √0.1.
PmscModel three_point_model(int region_count) {
  PmscModel m = testing::three_point_model({0, 1}, {0.1, 0.5});
  m.region_count = region_count;
  if (region_count == 1) {
    m.point_regions = {0, 0, 0};
    m.key_regions = {0, 0};
  } else if (region_count == 2) {
    m.point_regions = {0, 1, 1};
    m.key_regions = {0, 1};
  }
  return m;
}

TEST(LocalFailThrough, OneRegionBlendsExactlyLikeTheWholePose) {
  PmscModel m = three_point_model(1);
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(2), full(3);
  keys << 1, 1;
  full << 1, 1, 2;
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  const double alpha = (std::sqrt(0.1) - 0.1) / (0.5 - 0.1);  // eq. 11 by hand
  const LocalFailThrough local = local_fail_through(m, estimate);
  ASSERT_EQ(local.full_points, (std::vector<int>{0, 1, 2}));
  for (double a : local.full_point_blend_weights) EXPECT_NEAR(a, alpha, 1e-7);

  Eigen::VectorXf out(3);
  blend_partial(m, local, estimate.points, local.full_points, full, out);
  const double f_hat[] = {0.6, 1.2, 1.2};
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(out(i), alpha * full(i) + (1 - alpha) * f_hat[i], 1e-6) << i;
  // … and the whole-pose soft cache gives the same points.
  CachedPose cached;
  evaluate_cached(m, keys, &full, cached);
  ASSERT_EQ(cached.status, CacheStatus::kBlend);
  for (int i = 0; i < 3; ++i) EXPECT_FLOAT_EQ(out(i), cached.points(i)) << i;
}

TEST(LocalFailThrough, PartialBlendReadsOnlyThePointsThatNeedTheFullCalculation) {
  PmscModel m = three_point_model(2);
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(2);
  keys << 1, 1;
  PoseEstimate estimate;
  evaluate(m, keys, estimate);
  // Region errors |1 − 0.6| = 0.4 (blend, α₀ = 0.75) and |1 − 1.2| = 0.2 (blend, α₁ = 0.25):
  // with region thresholds [0.1, 0.5] for region 0 and [0.3, 0.5] for region 1 only region 0
  // (point 0) fails.
  m.region_epsilon = {{0.1, 0.5}, {0.3, 0.5}};
  const LocalFailThrough local = local_fail_through(m, estimate);
  ASSERT_EQ(local.full_points, (std::vector<int>{0}));
  EXPECT_NEAR(local.full_point_blend_weights[0], 0.75, 1e-6);

  // The caller sends point 0 and, needlessly, point 2 with a value that must not be read.
  const std::vector<int> given = {0, 2};
  Eigen::VectorXf values(2);
  values << 1.0f, std::numeric_limits<float>::quiet_NaN();
  Eigen::VectorXf out(3);
  blend_partial(m, local, estimate.points, given, values, out);
  EXPECT_NEAR(out(0), 0.75 * 1.0 + 0.25 * 0.6, 1e-6);
  EXPECT_EQ(out(1), estimate.points(1));
  EXPECT_EQ(out(2), estimate.points(2));

  EXPECT_TRUE(check_covers(local, given).ok());
  const Status missing = check_covers(local, {1, 2});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("point 0 needs the full calculation"), std::string::npos)
      << missing.error().message;
}

TEST(LocalFailThrough, CachedEvaluationComputesAndBlendsOnlyTheNeededPoints) {
  PmscModel m = three_point_model(2);
  ASSERT_TRUE(prepare_projection(m).ok());
  m.region_epsilon = {{0.1, 0.5}, {0.3, 0.5}};  // region 0 (point 0) blends with α = 0.75
  Eigen::VectorXf keys(2);
  keys << 1, 1;
  std::vector<std::vector<int>> asked;
  const PartialFullCalculation engine = [&](const std::vector<int>& points, Eigen::VectorXf& values) {
    asked.push_back(points);
    values = Eigen::VectorXf::Constant(static_cast<long>(points.size()), 3.0f);
    return true;
  };
  CachedPose out;
  LocalFailThrough local;
  ASSERT_TRUE(evaluate_cached_local(m, keys, {}, nullptr, engine, out, local).ok());
  // The whole-pose verdict is evaluate_cached's: e_key = √0.1 in [0.1, 0.5].
  EXPECT_EQ(out.status, CacheStatus::kBlend);
  EXPECT_NEAR(out.alpha, (std::sqrt(0.1) - 0.1) / 0.4, 1e-7);
  ASSERT_EQ(asked, (std::vector<std::vector<int>>{{0}}));
  EXPECT_FALSE(out.full_evaluation_needed);
  EXPECT_NEAR(out.points(0), 0.75 * 3.0 + 0.25 * 0.6, 1e-6);
  EXPECT_NEAR(out.points(1), 1.2, 1e-6);
  EXPECT_NEAR(out.points(2), 1.2, 1e-6);
  EXPECT_EQ(out.computed_full_values, Eigen::VectorXf::Constant(1, 3.0f));

  // Without an engine: the estimate, flagged; given values that miss point 0: refused.
  ASSERT_TRUE(evaluate_cached_local(m, keys, {}, nullptr, PartialFullCalculation(), out, local).ok());
  EXPECT_TRUE(out.full_evaluation_needed);
  EXPECT_NEAR(out.points(0), 0.6, 1e-6);
  const Eigen::VectorXf values = Eigen::VectorXf::Constant(1, 3.0f);
  const Status missing = evaluate_cached_local(m, keys, {2}, &values, engine, out, local);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kInvalidArgument);

  // A hit never asks the engine: keys on the subspace (f = 1.5·a has keys (0.5, 1)).
  keys << 0.5f, 1.0f;
  asked.clear();
  ASSERT_TRUE(evaluate_cached_local(m, keys, {}, nullptr, engine, out, local).ok());
  EXPECT_EQ(out.status, CacheStatus::kHit);
  EXPECT_TRUE(asked.empty());
  EXPECT_TRUE(local.full_points.empty());
}

TEST(LocalFailThrough, PartialFrameIsCompletedWithKeyValuesAndTheEstimate) {
  PmscModel m = three_point_model(2);
  ASSERT_TRUE(prepare_projection(m).ok());
  Eigen::VectorXf keys(2), values(1);
  keys << 1, 1;
  values << 5;  // point 2's full value
  const Eigen::VectorXf frame = complete_partial_frame(m, keys, {2}, values);
  // Points 0 and 1 are key points (their key values are f there); point 2 was given.
  EXPECT_EQ(frame, (Eigen::VectorXf(3) << 1, 1, 5).finished());
  // Without point 2 it is f̂ there: 1.8 · 2/3.
  const Eigen::VectorXf estimated = complete_partial_frame(m, keys, {}, Eigen::VectorXf());
  EXPECT_NEAR(estimated(2), 1.2, 1e-6);

  // The consistency check of issue #21 applies to the key points a partial frame holds.
  Eigen::VectorXf wrong_key(1);
  wrong_key << 0.0f;
  EXPECT_TRUE(check_full_values_at_keys(m, keys, {2}, values).ok());
  const Status bad = check_full_values_at_keys(m, keys, {1}, wrong_key);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("key point 1 (point 1)"), std::string::npos) << bad.error().message;
}

// A grid of n × n vertices whose motion signature is its column (one subspace direction whose
// amplitude grows along x), split into stripes of columns.
struct Grid {
  int n = 0;
  Eigen::MatrixXd signatures;  // n² × 1
  std::vector<int> regions;
  int col(long i) const { return static_cast<int>(i % n); }
};

Grid striped_grid(int n, int stripes) {
  Grid g;
  g.n = n;
  g.signatures.resize(static_cast<long>(n) * n, 1);
  for (long i = 0; i < g.signatures.rows(); ++i) {
    g.signatures(i, 0) = static_cast<double>(g.col(i)) / (n - 1);
    g.regions.push_back(std::min(stripes - 1, g.col(i) * stripes / n));
  }
  return g;
}

// The largest |α_i − α_j| over grid neighbours (right and down).
double largest_jump(const Grid& g, const std::vector<double>& alpha) {
  double jump = 0;
  for (int row = 0; row < g.n; ++row) {
    for (int col = 0; col < g.n; ++col) {
      const size_t i = static_cast<size_t>(row * g.n + col);
      if (col + 1 < g.n) jump = std::max(jump, std::abs(alpha[i] - alpha[i + 1]));
      if (row + 1 < g.n) jump = std::max(jump, std::abs(alpha[i] - alpha[i + static_cast<size_t>(g.n)]));
    }
  }
  return jump;
}

// α of every point (0 for the points local fail-through leaves to the estimate).
std::vector<double> point_alphas(const PmscModel& m, const std::vector<double>& region_errors) {
  std::vector<double> alpha(static_cast<size_t>(m.point_count), 0.0);
  const LocalFailThrough local = local_fail_through(m, 0, region_errors);
  for (size_t j = 0; j < local.full_points.size(); ++j) {
    alpha[static_cast<size_t>(local.full_points[j])] = local.full_point_blend_weights[j];
  }
  return alpha;
}

PmscModel grid_model(const Grid& g, int region_count) {
  PmscModel m;
  m.channel_count = 1;
  m.point_count = g.n * g.n;
  m.region_count = region_count;
  m.point_regions = g.regions;
  m.epsilon = {0.1, 0.2};
  return m;
}

TEST(LocalFailThrough, PointWeightsHaveNoSeamAcrossRegionBorders) {
  constexpr int n = 40;
  for (int stripes : {2, 3}) {
    SCOPED_TRACE(stripes);
    const Grid g = striped_grid(n, stripes);
    PmscModel m = grid_model(g, stripes);
    m.region_weights = soft_region_weights(g.signatures, g.regions, stripes);
    ASSERT_TRUE(check_region_weights(m).ok()) << check_region_weights(m).error().message;
    // Region verdicts: a miss (α = 1) next to a hit (α = 0), then a blend half-way (error 0.15).
    const std::vector<double> errors = {1.0, 0.0, 0.15};
    const std::vector<double> region_alpha = {1.0, 0.0, 0.5};
    const std::vector<double> alpha = point_alphas(m, {errors.begin(), errors.begin() + stripes});

    // Independent bound: between adjacent stripes r, s the weight ramps linearly over a band of
    // β·|c_r − c_s| in signature units, i.e. β·|c_r − c_s|·(n − 1) columns, so one column step
    // changes α by at most |α_r − α_s| over that many columns. Centroids from the construction.
    double bound = 0;
    std::vector<double> centroid(static_cast<size_t>(stripes), 0.0), count(static_cast<size_t>(stripes), 0.0);
    for (long i = 0; i < g.signatures.rows(); ++i) {
      centroid[static_cast<size_t>(g.regions[static_cast<size_t>(i)])] += g.signatures(i, 0);
      count[static_cast<size_t>(g.regions[static_cast<size_t>(i)])] += 1;
    }
    for (int r = 0; r < stripes; ++r) centroid[static_cast<size_t>(r)] /= count[static_cast<size_t>(r)];
    for (int r = 0; r + 1 < stripes; ++r) {
      const double band_columns =
          kRegionBorderBand * (centroid[static_cast<size_t>(r) + 1] - centroid[static_cast<size_t>(r)]) * (n - 1);
      bound = std::max(bound, std::abs(region_alpha[static_cast<size_t>(r)] - region_alpha[static_cast<size_t>(r) + 1]) /
                                  band_columns);
    }
    ASSERT_GT(bound, 0);
    ASSERT_LT(bound, 0.5);  // the band spans several vertices: the bound says something
    EXPECT_LE(largest_jump(g, alpha), bound * (1 + 1e-9));
    // Deep inside a region a point follows its region alone.
    EXPECT_EQ(alpha[0], 1.0);
    int first = -1, last = -1;
    for (int col = 0; col < n; ++col) {
      if (g.regions[static_cast<size_t>(col)] != 1) continue;
      if (first < 0) first = col;
      last = col;
    }
    EXPECT_EQ(alpha[static_cast<size_t>((first + last) / 2)], region_alpha[1]);

    // The hard regions of an old model switch from f to f̂ between two neighbours.
    m.region_weights.resize(0, 0);
    EXPECT_EQ(largest_jump(g, point_alphas(m, {errors.begin(), errors.begin() + stripes})), 1.0);
  }
}

TEST(LocalFailThrough, SoftWeightsArePartitionsOfUnityOverAtMostThreeRegions) {
  // Signatures in a plane, eight regions around a circle: junctions of many borders.
  const long N = 400;
  Eigen::MatrixXd signatures(N, 2);
  std::vector<int> regions;
  for (long i = 0; i < N; ++i) {
    const double angle = 2 * std::numbers::pi * static_cast<double>(i) / N;
    const double radius = 0.2 + 0.8 * static_cast<double>(i % 7) / 6;
    signatures.row(i) << radius * std::cos(angle), radius * std::sin(angle);
    regions.push_back(static_cast<int>(i * 8 / N));
  }
  const Eigen::MatrixXd w = soft_region_weights(signatures, regions, 8);
  for (long i = 0; i < N; ++i) {
    EXPECT_NEAR(w.row(i).sum(), 1.0, 1e-12) << i;
    EXPECT_LE((w.row(i).array() > 0).count(), kMaxRegionsPerPoint) << i;
    EXPECT_GE(w.row(i).minCoeff(), 0.0);
  }
  EXPECT_EQ(hard_region_weights(regions, 8).rowwise().sum(), Eigen::VectorXd::Ones(N));
}

TEST(LocalFailThrough, MalformedWeightsAreRefusedNamingTheMember) {
  PmscModel m = three_point_model(2);
  m.region_weights = hard_region_weights(m.point_regions, 2);
  ASSERT_TRUE(prepare_projection(m).ok());
  m.region_weights(1, 0) = 0.5;  // row 1 sums to 1.5
  Status status = prepare_projection(m);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("region_weights of point 1 sum to 1.5"), std::string::npos)
      << status.error().message;
  m.region_weights.resize(2, 2);
  status = prepare_projection(m);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("region_weights should be 3×2"), std::string::npos) << status.error().message;
}

TEST(LocalFailThrough, SoftWeightsSurviveTheContainerAndOldFilesLoadHard) {
  PmscModel m = three_point_model(2);
  m.region_weights.resize(3, 2);
  m.region_weights << 1, 0, 0.3, 0.7, 0, 1;
  ASSERT_TRUE(prepare_projection(m).ok());
  container::ModelContainer with;
  store(m, with);
  ASSERT_TRUE(with.has_section(kRegionWeightsSection));
  auto loaded = load(with, "with.asm");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->region_weights, m.region_weights);

  // A container written before the section existed: the same model, hard regions.
  PmscModel old = m;
  old.region_weights.resize(0, 0);
  container::ModelContainer without;
  store(old, without);
  ASSERT_FALSE(without.has_section(kRegionWeightsSection));
  loaded = load(without, "old.asm");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->region_weights.size(), 0);
  const LocalFailThrough local = local_fail_through(*loaded, 1.0, {1.0, 0.0});
  EXPECT_EQ(local.full_points, (std::vector<int>{0}));

  // A section of the wrong shape names itself.
  container::ModelContainer bad;
  store(m, bad);
  bad.set_matrix(kRegionWeightsSection, container::Float64Matrix(container::Float64Matrix::Zero(2, 2)));
  loaded = load(bad, "bad.asm");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("pmsc.region_weights"), std::string::npos) << loaded.error().message;
}

TEST(LocalFailThrough, MotionSignaturesAreBasisRowsScaledBySingularValues) {
  // The signature the trainer clusters is the one the memberships ramp over: point 1's rows (3, 4) · σ.
  Eigen::MatrixXd basis(4, 1);
  basis << 1, 2, 3, 4;
  Eigen::VectorXd sigma(1);
  sigma << 2;
  const Eigen::MatrixXd signatures = motion_signatures(basis, sigma, 2);
  ASSERT_EQ(signatures.rows(), 2);
  ASSERT_EQ(signatures.cols(), 2);
  EXPECT_EQ(signatures.row(1), (Eigen::RowVector2d(6, 8)));
}

TEST(LocalFailThrough, TrainingStoresSoftMembershipsOfItsRegions) {
  // 60 points moving in a random 3-dimensional subspace.
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  const Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(180, 3, [&] { return normal(rng); });
  FrameMatrix frames(20, 180);
  for (int f = 0; f < 20; ++f) frames.row(f) = (B * Eigen::Vector3d::NullaryExpr([&] { return normal(rng); })).cast<float>().transpose();
  TrainingOptions o;
  o.error_bound = 1e-4;
  o.error_tolerance = 1e-2;
  o.region_count = 4;
  auto model = train(frames, o, nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  ASSERT_GT(model->region_count, 1);
  ASSERT_EQ(model->region_weights.rows(), 60);
  ASSERT_EQ(model->region_weights.cols(), model->region_count);
  EXPECT_TRUE(check_region_weights(*model).ok());
}

}  // namespace
}  // namespace animspace::pmsc
