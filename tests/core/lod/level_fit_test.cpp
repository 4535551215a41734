// Placing a level's vertices (issue #26): with the closest points fixed the placement is the
// least-squares optimum (against a dense solve done here), a level pushed off a flat input comes
// back onto it, placement never raises the error it minimises, and a level's ε^l bounds the RMS
// over the poses P was averaged from of every input vertex's distance to the posed level.
// Influence simplification after placement removes what costs nothing when told to remove only
// that, keeps the exchange rule (a level's RMS grows by at most x times the fraction of
// influences it saves), and leaves ε^l a bound of the measured error.
#include "core/lod/level_fit.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "core/common/parallel.h"
#include "core/lod/levels.h"
#include "core/lod/simplify.h"
#include "core/lod/surface_distance.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;

// One bone with E[GᵀG] = I: y = p, so L2,2 is the Euclidean distance of (x, y, z) and the weight
// (always 1) adds nothing.
as::AnimationSpaceModel one_bone_model(const Eigen::MatrixXd& points, const FaceMatrix& faces) {
  as::AnimationSpaceModel m;
  m.skeleton.parents = {-1};
  m.skeleton.rest = {as::Transform::Identity()};
  m.faces = faces;
  m.positions.resize(4, points.cols());
  for (Eigen::Index v = 0; v < points.cols(); ++v) {
    m.positions.col(v) << points.col(v), 1;
    m.influences.bones.push_back(0);
    m.influences.offsets.push_back(static_cast<int32_t>(v + 1));
  }
  return m;
}

Eigen::Vector3d xyz(const as::AnimationSpaceModel& m, int v) { return m.positions.col(v).head<3>(); }

TEST(LevelFit, WithFixedClosestPointsThePlacementIsTheLeastSquaresOptimum) {
  // Level: one triangle. Input: the triangle's corners and points hovering over its inside, whose
  // closest points are their orthogonal projections. One round of converged Gauss–Seidel must
  // land on min Σ_o ‖x_o − Σ_c λ_oc v_c‖² over the three corners v_c, solved densely here.
  Eigen::MatrixXd corners(3, 3);
  corners << 0, 2, 0,  //
      0, 0, 2,         //
      0, 0, 0;
  std::mt19937 random(11);
  std::uniform_real_distribution<double> unit(0.05, 0.9);
  std::normal_distribution<double> lift(0, 0.2);
  Eigen::MatrixXd input(3, 3 + 12);
  input.leftCols(3) = corners;
  std::vector<Eigen::Vector3d> lambdas = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int k = 0; k < 12; ++k) {
    double s = unit(random), t = unit(random);
    if (s + t > 0.95) {
      s *= 0.5;
      t *= 0.5;
    }
    input.col(3 + k) = Eigen::Vector3d(2 * s, 2 * t, lift(random));
    lambdas.emplace_back(1 - s - t, s, t);
  }
  FaceMatrix one(1, 3);
  one << 0, 1, 2;
  const as::AnimationSpaceModel in = one_bone_model(input, FaceMatrix(0, 3));
  as::AnimationSpaceModel level = one_bone_model(corners, one);
  std::vector<int32_t> representative(static_cast<size_t>(input.cols()), 0);
  LevelFitOptions options;
  options.rounds = 1;
  options.sweeps = 400;
  ASSERT_TRUE(fit_level(in, Eigen::Matrix4d::Identity(), representative, level, options).ok());

  // Dense least squares: unknowns (v_0, v_1, v_2) ∈ R⁹.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3 * input.cols(), 9);
  Eigen::VectorXd b(3 * input.cols());
  for (Eigen::Index o = 0; o < input.cols(); ++o) {
    for (int c = 0; c < 3; ++c)
      A.block<3, 3>(3 * o, 3 * c) = lambdas[static_cast<size_t>(o)](c) * Eigen::Matrix3d::Identity();
    b.segment<3>(3 * o) = input.col(o);
  }
  const Eigen::VectorXd best = A.colPivHouseholderQr().solve(b);
  for (int c = 0; c < 3; ++c) {
    EXPECT_LT((xyz(level, c) - best.segment<3>(3 * c)).norm(), 1e-6) << "corner " << c;
  }
  EXPECT_DOUBLE_EQ(level.positions(3, 0), 1.0);  // the weight is kept
}

TEST(LevelFit, ALevelPushedOffAFlatInputComesBackOntoIt) {
  // Input: a 5 × 5 grid in z = 0. Level: its 3 × 3 sub-grid with every vertex lifted off the
  // plane by a different amount. The plane is the optimum (distance 0 for every input vertex).
  Eigen::MatrixXd grid(3, 25);
  for (int j = 0; j < 5; ++j) {
    for (int i = 0; i < 5; ++i) grid.col(5 * j + i) = Eigen::Vector3d(i, j, 0);
  }
  const auto grid_faces = [](int n, int stride_ids, const std::vector<int>& ids) {
    FaceMatrix f(2 * (n - 1) * (n - 1), 3);
    int r = 0;
    for (int j = 0; j + 1 < n; ++j) {
      for (int i = 0; i + 1 < n; ++i) {
        const int a = ids[static_cast<size_t>(j * stride_ids + i)],
                  b = ids[static_cast<size_t>(j * stride_ids + i + 1)];
        const int c = ids[static_cast<size_t>((j + 1) * stride_ids + i)],
                  d = ids[static_cast<size_t>((j + 1) * stride_ids + i + 1)];
        f.row(r++) << a, b, d;
        f.row(r++) << a, d, c;
      }
    }
    return f;
  };
  std::vector<int> fine(25), coarse(9);
  for (int k = 0; k < 25; ++k) fine[static_cast<size_t>(k)] = k;
  for (int k = 0; k < 9; ++k) coarse[static_cast<size_t>(k)] = k;
  const as::AnimationSpaceModel in = one_bone_model(grid, grid_faces(5, 5, fine));
  Eigen::MatrixXd lifted(3, 9);
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) lifted.col(3 * j + i) = Eigen::Vector3d(2 * i, 2 * j, 0.05 * (1 + 3 * j + i));
  }
  as::AnimationSpaceModel level = one_bone_model(lifted, grid_faces(3, 3, coarse));
  // Every input vertex goes to the nearest coarse vertex.
  std::vector<int32_t> representative(25);
  for (int j = 0; j < 5; ++j) {
    for (int i = 0; i < 5; ++i) representative[static_cast<size_t>(5 * j + i)] = 3 * ((j + 1) / 2) + (i + 1) / 2;
  }
  LevelFitOptions measure;
  measure.rounds = 0;
  as::AnimationSpaceModel unmoved = level;
  const LevelFit before = fit_level(in, Eigen::Matrix4d::Identity(), representative, unmoved, measure).value();
  EXPECT_GT(before.bound, 0.05);
  LevelFitOptions options;
  options.rounds = 20;
  options.sweeps = 20;
  const LevelFit after = fit_level(in, Eigen::Matrix4d::Identity(), representative, level, options).value();
  EXPECT_LT(after.bound, 1e-3 * before.bound);
  for (int v = 0; v < 9; ++v) EXPECT_NEAR(level.positions(2, v), 0, 1e-4) << "vertex " << v;
}

Points3d posed(const as::AnimationSpaceModel& m, const as::TransformList& G) {
  PointMatrix points;
  as::evaluate(m, G, points);
  return Points3d(points.cast<double>());
}

// Per input vertex of `input`, the RMS over `poses` of its distance to the posed `level`.
std::vector<double> rms_over_poses(const as::AnimationSpaceModel& input, const as::AnimationSpaceModel& level,
                                   const std::vector<as::TransformList>& poses) {
  std::vector<double> sum(static_cast<size_t>(input.vertex_count()), 0.0);
  for (const as::TransformList& G : poses) {
    const Points3d original = posed(input, G);
    const SurfaceDistance surface(posed(level, G), level.faces);
    for (Eigen::Index o = 0; o < original.rows(); ++o) {
      sum[static_cast<size_t>(o)] += distances_to_surface(original.row(o), surface).sum_of_squares;
    }
  }
  for (double& s : sum) s = std::sqrt(s / static_cast<double>(poses.size()));
  return sum;
}

double total_squares(const std::vector<double>& rms) {
  double total = 0;
  for (const double r : rms) total += r * r;
  return total;
}

TEST(LevelFit, EveryLevelsEpsilonBoundsTheRmsOverThePosesOfEveryInputVertex) {
  const testing::LodCase c = testing::arm_lod_case();
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  LodLevels placed = make_levels(*pm);
  const LodLevels unplaced = placed;
  ASSERT_GE(placed.count(), 3);
  ASSERT_TRUE(fit_levels(placed, c.metrics.P).ok());
  double previous = 0;
  for (int l = 1; l < placed.count(); ++l) {
    const LodLevel& level = placed.levels[static_cast<size_t>(l)];
    EXPECT_GE(level.epsilon, previous) << "level " << l;
    previous = level.epsilon;
    EXPECT_EQ(level.model.influences.bones, unplaced.levels[static_cast<size_t>(l)].model.influences.bones);
    ASSERT_TRUE(as::validate(level.model).ok()) << "level " << l;
    const std::vector<double> error = rms_over_poses(c.model, level.model, c.poses);
    for (size_t o = 0; o < error.size(); ++o) {
      EXPECT_LE(error[o], level.epsilon * (1 + 1e-6) + 1e-9) << "level " << l << " vertex " << o;
    }
    EXPECT_LT(total_squares(error),
              total_squares(rms_over_poses(c.model, unplaced.levels[static_cast<size_t>(l)].model, c.poses)))
        << "level " << l;
  }
}

// The closest points, the normal equations and the residuals are split over the cores, and a
// sweep moves one colour's vertices at a time (no two sharing a point): the levels must not depend
// on how many threads ran them. A character large enough that every split runs in two chunks.
TEST(LevelFit, TheLevelsAreTheSameOnOneThreadAndOnTwo) {
  const testing::LodCase c = testing::arm_lod_case(160, 16, 12);
  ASSERT_GE(c.model.vertex_count(), 2048);
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  const LodLevels cut = make_levels(*pm);
  ASSERT_GE(cut.count(), 3);
  LevelFitOptions options;
  options.influence_exchange = 0.5;
  LodLevels one = cut, two = cut;
  set_thread_limit(1);
  const auto on_one = fit_levels(one, c.metrics.P, options);
  set_thread_limit(2);
  const auto on_two = fit_levels(two, c.metrics.P, options);
  set_thread_limit(0);
  ASSERT_TRUE(on_one.ok()) << on_one.error().message;
  ASSERT_TRUE(on_two.ok()) << on_two.error().message;
  for (int l = 1; l < cut.count(); ++l) {
    const auto& a = one.levels[static_cast<size_t>(l)];
    const auto& b = two.levels[static_cast<size_t>(l)];
    EXPECT_NE(a.model.positions, cut.levels[static_cast<size_t>(l)].model.positions) << "level " << l << " moved";
    EXPECT_EQ(a.model.influences.bones, b.model.influences.bones) << "level " << l;
    EXPECT_TRUE(a.model.positions == b.model.positions) << "level " << l;
    EXPECT_EQ(a.epsilon, b.epsilon) << "level " << l;
  }
}

TEST(LevelFit, InfluencesThatCarryNothingAreRemovedAtNoCost) {
  // Two bones, P = I (y = p): every vertex of the level also names bone 1 with a zero vector, so
  // removing bone 1 moves nothing (§6.3's least correction is s = 0) while removing bone 0 moves
  // the vertex by its whole position. With exchange 0 exactly the bone-1 influences go.
  Eigen::MatrixXd corners(3, 3);
  corners << 0, 2, 0,  //
      0, 0, 2,         //
      0, 0, 0;
  Eigen::MatrixXd input_points(3, 6);
  input_points << corners, Eigen::MatrixXd(3, 3);
  input_points.rightCols(3) << 0.5, 1, 0.3,  //
      0.5, 0.3, 1,                           //
      0.1, -0.2, 0.15;
  FaceMatrix one(1, 3);
  one << 0, 1, 2;
  as::AnimationSpaceModel in = one_bone_model(input_points, FaceMatrix(0, 3));
  as::AnimationSpaceModel level = one_bone_model(corners, one);
  for (as::AnimationSpaceModel* m : {&in, &level}) {
    m->skeleton.parents = {-1, 0};
    m->skeleton.rest = {as::Transform::Identity(), as::Transform::Identity()};
  }
  as::InfluenceSets two;
  as::InfluenceVectors positions(4, 6);
  for (int v = 0; v < 3; ++v) {
    two.bones.insert(two.bones.end(), {0, 1});
    two.offsets.push_back(2 * (v + 1));
    positions.col(2 * v) = level.positions.col(v);
    positions.col(2 * v + 1).setZero();
  }
  level.influences = two;
  level.positions = positions;
  ASSERT_TRUE(as::validate(level).ok());
  std::vector<int32_t> representative = {0, 1, 2, 0, 1, 2};
  LevelFitOptions options;
  options.influence_exchange = 0;
  const LevelFit fit = fit_level(in, Eigen::MatrixXd::Identity(8, 8), representative, level, options).value();
  EXPECT_EQ(fit.influences_before, 6);
  EXPECT_EQ(fit.influences, 3);
  EXPECT_EQ(level.influences.bones, (std::vector<int32_t>{0, 0, 0}));
  EXPECT_LE(fit.rms, fit.rms_before * (1 + 1e-9) + 1e-12);
  ASSERT_TRUE(as::validate(level).ok());
}

TEST(LevelFit, ServedLevelsKeepTheExchangeRuleAndTheirEpsilonBoundsTheError) {
  const testing::LodCase c = testing::arm_lod_case();
  LevelBuildOptions options;  // the served levels: placed, then influences simplified
  ASSERT_GE(options.influence_exchange, 0);
  auto built = build_levels(c.model, c.metrics, options);
  ASSERT_TRUE(built.ok()) << built.error().message;
  LevelBuildOptions collapses_only = options;
  collapses_only.influence_simplification = false;
  auto plain = build_levels(c.model, c.metrics, collapses_only);
  ASSERT_TRUE(plain.ok()) << plain.error().message;
  const LodLevels& lods = built->lods;
  ASSERT_GE(lods.count(), 3);
  ASSERT_EQ(built->fits.size(), static_cast<size_t>(lods.count()));
  ASSERT_EQ(plain->lods.count(), lods.count());
  int removed = 0;
  for (int l = 1; l < lods.count(); ++l) {
    const LodLevel& level = lods.levels[static_cast<size_t>(l)];
    const LodLevel& same_cut = plain->lods.levels[static_cast<size_t>(l)];
    const LevelFit& fit = built->fits[static_cast<size_t>(l)];
    ASSERT_TRUE(as::validate(level.model).ok()) << "level " << l;
    EXPECT_EQ(level.vertex_ids, same_cut.vertex_ids) << "level " << l;
    // Before its removals, the level is the collapses-only level, placed the same way.
    EXPECT_EQ(fit.influences_before, same_cut.model.influences.influence_count()) << "level " << l;
    EXPECT_NEAR(fit.rms_before, plain->fits[static_cast<size_t>(l)].rms, 1e-12) << "level " << l;
    EXPECT_EQ(fit.influences, level.model.influences.influence_count()) << "level " << l;
    removed += fit.influences_before - fit.influences;
    // The exchange rule: the fit's own RMS, and the error measured across the poses (which the
    // fit's closest points bound from above), both within (1 + x · saved) of the level before.
    const double saved = static_cast<double>(fit.influences_before - fit.influences) / fit.influences_before;
    const double allowed = (1 + options.influence_exchange * saved) * fit.rms_before;
    EXPECT_LE(fit.rms, allowed * (1 + 1e-9) + 1e-12) << "level " << l;
    const std::vector<double> error = rms_over_poses(c.model, level.model, c.poses);
    EXPECT_LE(std::sqrt(total_squares(error) / static_cast<double>(error.size())), allowed * (1 + 1e-6) + 1e-12)
        << "level " << l;
    for (size_t o = 0; o < error.size(); ++o) {
      EXPECT_LE(error[o], level.epsilon * (1 + 1e-6) + 1e-9) << "level " << l << " vertex " << o;
    }
  }
  EXPECT_GT(removed, 0);
}

}  // namespace
}  // namespace animspace::lod
