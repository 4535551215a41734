// Tests of influence simplification (Merry 2007 §6.3, Appendix B.1).
//
// P comes from real poses of a generated skeleton (fixed translations, so it is singular,
// Appendix B.3). References are computed here in the full 4b-dimensional animation space: the
// §6.3 constraints plus "s_j = 0 off the vertex's bones" as rows of one big A, solved by a
// brute-force null-space method with the full P, independent of the solver under test.
#include "core/lod/influence_simplification.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/animspace/metrics.h"
#include "core/lod/vertex_state.h"
#include "tests/support/animspace_fixtures.h"
#include "tests/support/constrained_least_squares_reference.h"

namespace animspace::lod {
namespace {

using animation_space::InfluenceVectors;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using testing::null_space_solution;

constexpr int kBones = 6;

// P = E[GᵀG] averaged over random poses (rotations, fixed translations) of a random skeleton.
MatrixXd pose_metric(uint64_t seed, int bones = kBones, int pose_count = 40) {
  const animation_space::Skeleton skeleton = testing::random_skeleton(bones, seed);
  std::mt19937_64 engine(seed + 1000);
  std::vector<animation_space::TransformList> poses;
  for (int n = 0; n < pose_count; ++n) poses.push_back(testing::random_pose(skeleton, engine, 1.2));
  const Result<animation_space::AnimationSpaceMetrics> metrics = animation_space::metrics_from_poses(skeleton, poses);
  EXPECT_TRUE(metrics.ok()) << metrics.error().message;
  return metrics->P;
}

// A vertex on `bones` with random influences of total weight 1 and, optionally, random tangents
// of weight 0.
VertexState random_vertex(const std::vector<int32_t>& bones, std::mt19937_64& engine, bool tangents) {
  std::normal_distribution<double> normal;
  const auto k = static_cast<Eigen::Index>(bones.size());
  auto random_columns = [&](double weight) {
    InfluenceVectors v(4, k);
    for (Eigen::Index j = 0; j < k; ++j) v.col(j) = Eigen::Vector4d(normal(engine), normal(engine), normal(engine), normal(engine));
    v.row(3).array() += (weight - v.row(3).sum()) / static_cast<double>(k);
    return v;
  };
  VertexState state;
  state.bones = bones;
  state.position = random_columns(1.0);
  if (tangents) {
    state.tangent_s = random_columns(0.0);
    state.tangent_t = random_columns(0.0);
  }
  return state;
}

// The dense 4b-vector of 4 × k columns on `bones`.
VectorXd dense(const std::vector<int32_t>& bones, const InfluenceVectors& v, Eigen::Index size) {
  VectorXd out = VectorXd::Zero(size);
  for (size_t j = 0; j < bones.size(); ++j) out.segment<4>(4 * bones[j]) = v.col(static_cast<Eigen::Index>(j));
  return out;
}

// The full-space reference correction (dense) that removes the bones `removed` from v (a
// position or tangent on `bones`): s_i = −v_i for i removed, Σ_j s_j,w = 0, s_j = 0 for j not in
// `bones`; least sᵀPs, then least ‖s‖.
VectorXd full_space_correction(const MatrixXd& P, const std::vector<int32_t>& bones, const InfluenceVectors& v,
                               const std::vector<int32_t>& removed) {
  const Eigen::Index b = P.rows() / 4;
  std::vector<Eigen::VectorXd> rows;
  std::vector<double> rhs;
  const VectorXd v_dense = dense(bones, v, P.rows());
  auto unit_row = [&](Eigen::Index index, double value) {
    VectorXd row = VectorXd::Zero(P.rows());
    row(index) = 1;
    rows.push_back(row);
    rhs.push_back(value);
  };
  for (const int32_t i : removed) {
    for (int c = 0; c < 4; ++c) unit_row(4 * i + c, -v_dense(4 * i + c));
  }
  VectorXd weight = VectorXd::Zero(P.rows());
  for (Eigen::Index j = 0; j < b; ++j) weight(4 * j + 3) = 1;
  rows.push_back(weight);
  rhs.push_back(0);
  for (Eigen::Index j = 0; j < b; ++j) {
    if (std::find(bones.begin(), bones.end(), static_cast<int32_t>(j)) != bones.end()) continue;
    for (int c = 0; c < 4; ++c) unit_row(4 * j + c, 0);
  }
  MatrixXd A(static_cast<Eigen::Index>(rows.size()), P.rows());
  VectorXd target(static_cast<Eigen::Index>(rows.size()));
  for (size_t r = 0; r < rows.size(); ++r) {
    A.row(static_cast<Eigen::Index>(r)) = rows[r].transpose();
    target(static_cast<Eigen::Index>(r)) = rhs[r];
  }
  return null_space_solution(P, A, target);
}

std::vector<int32_t> without(std::vector<int32_t> bones, int32_t bone) {
  bones.erase(std::find(bones.begin(), bones.end(), bone));
  return bones;
}

int slot_of(const std::vector<int32_t>& bones, int32_t bone) {
  return static_cast<int>(std::find(bones.begin(), bones.end(), bone) - bones.begin());
}

// Random strictly increasing sets of `k` bones out of `bone_count`.
std::vector<int32_t> random_bones(int k, std::mt19937_64& engine, int bone_count = kBones) {
  std::set<int32_t> chosen;
  while (static_cast<int>(chosen.size()) < k) {
    chosen.insert(std::uniform_int_distribution<int32_t>(0, bone_count - 1)(engine));
  }
  return {chosen.begin(), chosen.end()};
}

TEST(InfluenceSimplification, MetricFromPosesIsSingular) {
  // The premise of the tie-break tests: fixed translations give P a null space (Appendix B.3).
  const MatrixXd P = pose_metric(1);
  const VectorXd lambda = Eigen::SelfAdjointEigenSolver<MatrixXd>(P).eigenvalues();
  int zeros = 0;
  for (Eigen::Index i = 0; i < lambda.size(); ++i) zeros += lambda(i) <= 1e-12 * lambda.maxCoeff() ? 1 : 0;
  EXPECT_GE(zeros, kBones - 1);
  // And the smallest positive eigenvalue is well clear of the rounding of the zero ones.
  EXPECT_GT(lambda(zeros), 1e-6 * lambda.maxCoeff());
}

TEST(InfluenceSimplification, ApplyKeepsWeightOneAndDropsTheBone) {
  const MatrixXd P = pose_metric(2);
  std::mt19937_64 engine(3);
  for (int trial = 0; trial < 20; ++trial) {
    InfluenceSimplifier simplifier(P);
    VertexState state = random_vertex(random_bones(2 + trial % 3, engine), engine, false);
    const std::vector<int32_t> bones = state.bones;
    const Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
    ASSERT_TRUE(removal.ok()) << removal.error().message;
    ASSERT_EQ(removal->bone, bones[static_cast<size_t>(removal->slot)]);
    EXPECT_EQ(removal->correction.col(removal->slot), -state.position.col(removal->slot));
    simplifier.apply(*removal, state);
    EXPECT_EQ(state.bones, without(bones, removal->bone));
    ASSERT_EQ(state.position.cols(), static_cast<Eigen::Index>(bones.size()) - 1);
    EXPECT_NEAR(state.position.row(3).sum(), 1.0, 1e-12);
    EXPECT_FALSE(state.has_tangents());
  }
}

// A metric from few poses has many near-null directions, which put pivots of the solver near the
// floor that splits P's null space off; the cow rig's levels built from 16 sampled poses drifted
// to p̲ = 0.999996 that way. Removal after removal, down to one influence, p̲ must stay 1.
TEST(InfluenceSimplification, AMetricFromFewPosesStillKeepsWeightOne) {
  constexpr int kManyBones = 16;
  for (const int pose_count : {2, 4, 8, 16}) {
    const MatrixXd P = pose_metric(7, kManyBones, pose_count);
    InfluenceSimplifier simplifier(P);
    std::mt19937_64 engine(11);
    double worst = 0;
    for (int trial = 0; trial < 40; ++trial) {
      VertexState state = random_vertex(random_bones(8, engine, kManyBones), engine, false);
      while (state.influence_count() > 1) {
        const Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
        ASSERT_TRUE(removal.ok()) << removal.error().message;
        simplifier.apply(*removal, state);
        worst = std::max(worst, std::abs(state.position.row(3).sum() - 1.0));
      }
    }
    EXPECT_LT(worst, 1e-12) << pose_count << " poses";
  }
}

TEST(InfluenceSimplification, CostIsDenseL22NormOfCorrection) {
  const MatrixXd P = pose_metric(4);
  std::mt19937_64 engine(5);
  InfluenceSimplifier simplifier(P);
  for (int trial = 0; trial < 10; ++trial) {
    const VertexState state = random_vertex(random_bones(2 + trial % 4, engine), engine, false);
    for (int slot = 0; slot < state.influence_count(); ++slot) {
      const Result<InfluenceRemoval> removal = simplifier.removal(state, slot);
      ASSERT_TRUE(removal.ok()) << removal.error().message;
      const VectorXd s = dense(state.bones, removal->correction, P.rows());
      EXPECT_NEAR(s.segment<4>(4 * state.bones[static_cast<size_t>(slot)]).norm(),
                  state.position.col(slot).norm(), 1e-14 * state.position.col(slot).norm());
      const double expected = std::sqrt(std::max(0.0, s.dot(P * s)));
      EXPECT_NEAR(removal->cost, expected, 1e-12 * std::max(1.0, expected));
    }
  }
}

TEST(InfluenceSimplification, CorrectionMatchesFullSpaceBruteForce) {
  for (const uint64_t seed : {6u, 7u, 8u}) {
    const MatrixXd P = pose_metric(seed);
    std::mt19937_64 engine(seed + 50);
    InfluenceSimplifier simplifier(P);
    for (int trial = 0; trial < 6; ++trial) {
      const VertexState state = random_vertex(random_bones(2 + trial % 4, engine), engine, false);
      for (int slot = 0; slot < state.influence_count(); ++slot) {
        SCOPED_TRACE("seed " + std::to_string(seed) + ", trial " + std::to_string(trial) + ", slot " +
                     std::to_string(slot));
        const Result<InfluenceRemoval> removal = simplifier.removal(state, slot);
        ASSERT_TRUE(removal.ok()) << removal.error().message;
        const VectorXd s = dense(state.bones, removal->correction, P.rows());
        const VectorXd reference =
            full_space_correction(P, state.bones, state.position, {state.bones[static_cast<size_t>(slot)]});
        const double scale = std::max(1.0, reference.norm());
        EXPECT_LE((s - reference).norm(), 1e-8 * scale) << "s   = " << s.transpose() << "\nref = " << reference.transpose();
        EXPECT_NEAR(removal->cost * removal->cost, reference.dot(P * reference),
                    1e-9 * std::max(1.0, reference.dot(P * reference)));
        EXPECT_NEAR(s.norm(), reference.norm(), 1e-8 * scale);
      }
    }
  }
}

TEST(InfluenceSimplification, CheapestRemovalPicksTheMinimumCostSlot) {
  const MatrixXd P = pose_metric(9);
  std::mt19937_64 engine(10);
  InfluenceSimplifier simplifier(P);
  for (int trial = 0; trial < 15; ++trial) {
    const VertexState state = random_vertex(random_bones(2 + trial % 4, engine), engine, false);
    const Result<InfluenceRemoval> cheapest = simplifier.cheapest_removal(state);
    ASSERT_TRUE(cheapest.ok()) << cheapest.error().message;
    int best_slot = -1;
    double best_cost = 0;
    for (int slot = 0; slot < state.influence_count(); ++slot) {
      const Result<InfluenceRemoval> removal = simplifier.removal(state, slot);
      ASSERT_TRUE(removal.ok()) << removal.error().message;
      EXPECT_LE(cheapest->cost, removal->cost);
      if (best_slot < 0 || removal->cost < best_cost) {
        best_slot = slot;
        best_cost = removal->cost;
      }
    }
    EXPECT_EQ(cheapest->slot, best_slot);
    EXPECT_EQ(cheapest->bone, state.bones[static_cast<size_t>(best_slot)]);
    EXPECT_EQ(cheapest->cost, best_cost);
  }
}

TEST(InfluenceSimplification, SequentialRemovalsEqualOneShotRemoval) {
  // Appendix B.1: removing bone a, then bone c from the result, lands where removing both from
  // the original position at once does.
  for (const uint64_t seed : {11u, 12u}) {
    const MatrixXd P = pose_metric(seed);
    std::mt19937_64 engine(seed + 70);
    InfluenceSimplifier simplifier(P);
    for (int trial = 0; trial < 8; ++trial) {
      VertexState state = random_vertex(random_bones(3 + trial % 3, engine), engine, false);
      const VertexState original = state;
      const int first_slot = std::uniform_int_distribution<int>(0, state.influence_count() - 1)(engine);
      const int32_t first = state.bones[static_cast<size_t>(first_slot)];
      const std::vector<int32_t> rest = without(state.bones, first);
      const int32_t second = rest[std::uniform_int_distribution<size_t>(0, rest.size() - 1)(engine)];
      SCOPED_TRACE("seed " + std::to_string(seed) + ", trial " + std::to_string(trial));

      const Result<InfluenceRemoval> one = simplifier.removal(state, first_slot);
      ASSERT_TRUE(one.ok()) << one.error().message;
      simplifier.apply(*one, state);
      const Result<InfluenceRemoval> two = simplifier.removal(state, slot_of(state.bones, second));
      ASSERT_TRUE(two.ok()) << two.error().message;
      simplifier.apply(*two, state);
      EXPECT_EQ(state.bones, without(rest, second));

      const VectorXd reference = dense(original.bones, original.position, P.rows()) +
                                 full_space_correction(P, original.bones, original.position, {first, second});
      const VectorXd result = dense(state.bones, state.position, P.rows());
      EXPECT_LE((result - reference).norm(), 1e-8 * std::max(1.0, reference.norm()))
          << "two steps = " << result.transpose() << "\none shot  = " << reference.transpose();
      EXPECT_NEAR(state.position.row(3).sum(), 1.0, 1e-12);
    }
  }
}

TEST(InfluenceSimplification, TangentsKeepWeightZeroAndAreOrthonormal) {
  const MatrixXd P = pose_metric(13);
  std::mt19937_64 engine(14);
  InfluenceSimplifier simplifier(P);
  for (int trial = 0; trial < 12; ++trial) {
    VertexState state = random_vertex(random_bones(2 + trial % 4, engine), engine, true);
    const VertexState before = state;
    const Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
    ASSERT_TRUE(removal.ok()) << removal.error().message;
    simplifier.apply(*removal, state);
    ASSERT_TRUE(state.has_tangents());
    ASSERT_EQ(state.tangent_s.cols(), state.influence_count());
    ASSERT_EQ(state.tangent_t.cols(), state.influence_count());
    EXPECT_NEAR(state.tangent_s.row(3).sum(), 0.0, 1e-12);
    EXPECT_NEAR(state.tangent_t.row(3).sum(), 0.0, 1e-12);
    const VectorXd s = dense(state.bones, state.tangent_s, P.rows());
    const VectorXd t = dense(state.bones, state.tangent_t, P.rows());
    EXPECT_NEAR(s.dot(P * s), 1.0, 1e-10);
    EXPECT_NEAR(t.dot(P * t), 1.0, 1e-10);
    EXPECT_NEAR(s.dot(P * t), 0.0, 1e-10);

    // s is the full-space corrected tangent, normalised; t lies in the plane of the two
    // corrected tangents.
    const VectorXd s_ref = dense(before.bones, before.tangent_s, P.rows()) +
                           full_space_correction(P, before.bones, before.tangent_s, {removal->bone});
    const VectorXd t_ref = dense(before.bones, before.tangent_t, P.rows()) +
                           full_space_correction(P, before.bones, before.tangent_t, {removal->bone});
    EXPECT_LE((s - s_ref / std::sqrt(s_ref.dot(P * s_ref))).norm(), 1e-8 * std::max(1.0, s.norm()));
    MatrixXd plane(P.rows(), 2);
    plane << s_ref, t_ref;
    const VectorXd t_in_plane = plane * plane.colPivHouseholderQr().solve(t);
    EXPECT_LE((t - t_in_plane).norm(), 1e-8 * std::max(1.0, t.norm()));
  }
}

TEST(InfluenceSimplification, DegenerateTangentIsLeftUnnormalised) {
  // A zero tangent stays zero (no division by a zero L2,2 norm), the other is still normalised.
  const MatrixXd P = pose_metric(15);
  std::mt19937_64 engine(16);
  InfluenceSimplifier simplifier(P);
  VertexState state = random_vertex({1, 3, 4}, engine, true);
  state.tangent_s.setZero();
  const Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
  ASSERT_TRUE(removal.ok()) << removal.error().message;
  simplifier.apply(*removal, state);
  EXPECT_TRUE(state.tangent_s.allFinite());
  EXPECT_EQ(state.tangent_s.norm(), 0.0);
  const VectorXd t = dense(state.bones, state.tangent_t, P.rows());
  EXPECT_NEAR(t.dot(P * t), 1.0, 1e-10);
}

TEST(InfluenceSimplification, OperatorIsCachedPerBonesAndSlot) {
  const MatrixXd P = pose_metric(17);
  std::mt19937_64 engine(18);
  {
    InfluenceSimplifier simplifier(P);
    const VertexState a = random_vertex({1, 4}, engine, false);
    const VertexState b = random_vertex({1, 4}, engine, false);
    ASSERT_TRUE(simplifier.removal(a, 1).ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 1u);
    ASSERT_TRUE(simplifier.removal(b, 1).ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 1u);
    ASSERT_TRUE(simplifier.removal(b, 0).ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 2u);
  }
  {
    // cheapest_removal tries every slot: k operators for the first vertex, none new for a
    // second vertex on the same bones.
    InfluenceSimplifier simplifier(P);
    const VertexState a = random_vertex({0, 2, 5}, engine, true);
    const VertexState b = random_vertex({0, 2, 5}, engine, true);
    Result<InfluenceRemoval> removal = simplifier.cheapest_removal(a);
    ASSERT_TRUE(removal.ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 3u);
    VertexState applied = a;
    simplifier.apply(*removal, applied);  // the tangents reuse the position's operator
    EXPECT_EQ(simplifier.cached_operator_count(), 3u);
    ASSERT_TRUE(simplifier.cheapest_removal(b).ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 3u);
    ASSERT_TRUE(simplifier.cheapest_removal(random_vertex({0, 2}, engine, false)).ok());
    EXPECT_EQ(simplifier.cached_operator_count(), 5u);
  }
}

TEST(InfluenceSimplification, WorksOnModelVerticesDownToOneInfluence) {
  const animation_space::Skeleton skeleton = testing::random_skeleton(kBones, 19);
  const animation_space::AnimationSpaceModel model = testing::random_model(skeleton, 30, 20);
  InfluenceSimplifier simplifier(pose_metric(19));
  for (int v = 0; v < model.vertex_count(); ++v) {
    VertexState state = vertex_state(model, v);
    while (state.influence_count() > 1) {
      const Result<InfluenceRemoval> removal = simplifier.cheapest_removal(state);
      ASSERT_TRUE(removal.ok()) << removal.error().message;
      EXPECT_GE(removal->cost, 0.0);
      simplifier.apply(*removal, state);
      EXPECT_NEAR(state.position.row(3).sum(), 1.0, 1e-12);
    }
    // One influence of weight 1 is left.
    EXPECT_NEAR(state.position(3, 0), 1.0, 1e-12);
  }
}

TEST(InfluenceSimplification, Errors) {
  const MatrixXd P = pose_metric(21);
  std::mt19937_64 engine(22);
  InfluenceSimplifier simplifier(P);
  const VertexState single = random_vertex({3}, engine, false);
  const Result<InfluenceRemoval> cheapest = simplifier.cheapest_removal(single);
  ASSERT_FALSE(cheapest.ok());
  EXPECT_EQ(cheapest.error().code, ErrorCode::kFailedPrecondition);
  const Result<InfluenceRemoval> direct = simplifier.removal(single, 0);
  ASSERT_FALSE(direct.ok());
  EXPECT_EQ(direct.error().code, ErrorCode::kFailedPrecondition);
  const VertexState empty;
  ASSERT_FALSE(simplifier.cheapest_removal(empty).ok());
  EXPECT_EQ(simplifier.cheapest_removal(empty).error().code, ErrorCode::kFailedPrecondition);

  const VertexState pair = random_vertex({1, 2}, engine, false);
  for (const int slot : {-1, 2}) {
    const Result<InfluenceRemoval> out_of_range = simplifier.removal(pair, slot);
    ASSERT_FALSE(out_of_range.ok());
    EXPECT_EQ(out_of_range.error().code, ErrorCode::kOutOfRange);
  }

  const VertexState outside = random_vertex({1, kBones}, engine, false);
  const Result<InfluenceRemoval> bad_bone = simplifier.cheapest_removal(outside);
  ASSERT_FALSE(bad_bone.ok());
  EXPECT_EQ(bad_bone.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(bad_bone.error().message.find(std::to_string(kBones)), std::string::npos);
  EXPECT_EQ(simplifier.cached_operator_count(), 0u);
}

}  // namespace
}  // namespace animspace::lod
