// The progressive mesh (Merry 2007 ch. 6): hand-worked collapse costs, topology and normal guards
// at every step, exact replay, and influence removals checked against Monte-Carlo over the poses
// P was built from.
#include "core/lod/simplify.h"

#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <string_view>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "core/animspace/skeleton.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;
using testing::arm_lod_case;
using testing::flat_sheet_case;
using testing::LodCase;
using testing::pyramid_case;

Eigen::Vector3d rest_point(const as::Skeleton& skeleton, const VertexState& s) {
  Eigen::Vector4d v = Eigen::Vector4d::Zero();
  for (size_t k = 0; k < s.bones.size(); ++k) {
    v += skeleton.rest[static_cast<size_t>(s.bones[k])] * s.position.col(static_cast<Eigen::Index>(k));
  }
  return v.head<3>();
}

Eigen::Vector3d posed_point(const as::TransformList& G, const VertexState& s) {
  Eigen::Vector4d v = Eigen::Vector4d::Zero();
  for (size_t k = 0; k < s.bones.size(); ++k) {
    v += G[static_cast<size_t>(s.bones[k])] * s.position.col(static_cast<Eigen::Index>(k));
  }
  return v.head<3>();
}

void expect_same_model(const as::AnimationSpaceModel& a, const as::AnimationSpaceModel& b) {
  EXPECT_EQ(a.influences.offsets, b.influences.offsets);
  EXPECT_EQ(a.influences.bones, b.influences.bones);
  EXPECT_EQ(a.positions, b.positions);  // bit for bit
  EXPECT_EQ(a.tangent_s, b.tangent_s);
  EXPECT_EQ(a.tangent_t, b.tangent_t);
  EXPECT_EQ(a.faces, b.faces);
}

// Every live face has three distinct live corners, every directed edge appears once (consistent
// orientation) and every undirected edge bounds at most two faces (manifold).
void expect_manifold(const MeshState& state, size_t step) {
  std::map<std::pair<int, int>, int> directed;
  for (int f = 0; f < static_cast<int>(state.faces().rows()); ++f) {
    if (!state.face_alive(f)) continue;
    for (int c = 0; c < 3; ++c) {
      const int a = state.faces()(f, c), b = state.faces()(f, (c + 1) % 3);
      ASSERT_TRUE(state.vertex_alive(a)) << "step " << step << " face " << f;
      ASSERT_NE(a, b) << "step " << step << " face " << f;
      const int uses = ++directed[std::make_pair(a, b)];
      ASSERT_EQ(uses, 1) << "step " << step << ": edge " << a << "→" << b << " twice";
    }
  }
}

TEST(ProgressiveMesh, FlatSheetCollapsesCostNothing) {
  // One rigid bone: L2,2 is the Euclidean distance, the flattening of a flat one-ring is the
  // plane itself, so every new triangle interpolates exactly the points it replaces.
  const LodCase c = flat_sheet_case(6);
  SimplifyOptions options;
  options.min_vertices = 4;
  auto pm = build_progressive_mesh(c.model, c.metrics, options);
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  ASSERT_GT(pm->steps.size(), 30u);
  for (const Simplification& step : pm->steps) {
    EXPECT_EQ(step.kind, SimplificationKind::kEdgeCollapse);
    // cᵀ·gram·c of a zero deviation rounds to ~1e-16 (unit edges); its square root to ~1e-8.
    EXPECT_NEAR(step.cost, 0, 1e-6) << "collapse of " << step.vertex << " into " << step.target;
  }
}

TEST(ProgressiveMesh, QuadricOrderKeepsTheGuardsAndReplaysExactly) {
  // Ordering by quadric memory changes which steps come first, not what a step is allowed to do:
  // a flat sheet still costs nothing, and the arm's sequence replays to its base mesh.
  SimplifyOptions options;
  options.cost = CollapseCost::kQuadric;
  {
    const LodCase c = flat_sheet_case(6);
    auto pm = build_progressive_mesh(c.model, c.metrics, options);
    ASSERT_TRUE(pm.ok()) << pm.error().message;
    ASSERT_GT(pm->steps.size(), 30u);
    for (const Simplification& step : pm->steps) EXPECT_NEAR(step.cost, 0, 1e-6);
  }
  const LodCase c = arm_lod_case();
  auto pm = build_progressive_mesh(c.model, c.metrics, options);
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  EXPECT_LT(pm->base.vertex_count(), 10);
  MeshState state = MeshState::from_model(c.model);
  for (size_t k = 0; k < pm->steps.size(); ++k) {
    state.apply(pm->steps[k]);
    expect_manifold(state, k);
    if (::testing::Test::HasFatalFailure()) return;
  }
  expect_same_model(state.to_model(pm->skeleton), pm->base);
  expect_same_model(pm->state_after(0).to_model(pm->skeleton), c.model);
}

TEST(ProgressiveMesh, PyramidApexCostsItsHeight) {
  // Apex u = (0,0,h) over a unit square ring: collapsing u into a corner leaves the flat square,
  // whose point at u's parameter (the centre, on the new diagonal) is (0,0,0): deviation h.
  const double h = 0.1;
  const LodCase c = pyramid_case(h);
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  ASSERT_EQ(pm->steps.size(), 1u);  // 5 vertices, stop at 4
  EXPECT_EQ(pm->steps[0].vertex, 0);
  EXPECT_NEAR(pm->steps[0].cost, h, 1e-12);
  EXPECT_EQ(pm->steps[0].removed_faces.size(), 2u);
  EXPECT_EQ(pm->base.faces.rows(), 2);
}

TEST(ProgressiveMesh, ReplaysToTheInputExactly) {
  const LodCase c = arm_lod_case();
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  EXPECT_LT(pm->base.vertex_count(), 10);
  std::vector<int32_t> ids;
  const as::AnimationSpaceModel full = pm->state_after(0).to_model(pm->skeleton, &ids);
  expect_same_model(full, c.model);
  for (size_t v = 0; v < ids.size(); ++v) EXPECT_EQ(ids[v], static_cast<int32_t>(v));
  // Applying every step forward from the input lands on the stored base mesh.
  MeshState state = MeshState::from_model(c.model);
  for (const Simplification& step : pm->steps) state.apply(step);
  expect_same_model(state.to_model(pm->skeleton), pm->base);
}

TEST(ProgressiveMesh, EveryStepKeepsTheMeshManifoldAndUnflipped) {
  const LodCase c = arm_lod_case();
  SimplifyOptions options;
  options.max_normal_deviation_degrees = 60;
  auto pm = build_progressive_mesh(c.model, c.metrics, options);
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  MeshState state = MeshState::from_model(c.model);
  const double cos_limit = std::cos(60.0 * std::numbers::pi / 180.0);
  int collapses = 0;
  for (size_t k = 0; k < pm->steps.size(); ++k) {
    const Simplification& step = pm->steps[k];
    if (step.kind == SimplificationKind::kEdgeCollapse) {
      ++collapses;
      // Normals of the faces that move, in the rest pose, before and after.
      std::vector<Eigen::Vector3d> before;
      for (const int32_t f : step.moved_faces) {
        const auto corner = [&](int i) { return rest_point(c.model.skeleton, state.vertex(state.faces()(f, i))); };
        before.push_back((corner(1) - corner(0)).cross(corner(2) - corner(0)));
      }
      state.apply(step);
      for (size_t i = 0; i < step.moved_faces.size(); ++i) {
        const int32_t f = step.moved_faces[i];
        const auto corner = [&](int j) { return rest_point(c.model.skeleton, state.vertex(state.faces()(f, j))); };
        const Eigen::Vector3d after = (corner(1) - corner(0)).cross(corner(2) - corner(0));
        ASSERT_GT(after.norm(), 0) << "step " << k;
        EXPECT_GE(before[i].dot(after), cos_limit * before[i].norm() * after.norm() - 1e-12) << "step " << k;
      }
    } else {
      state.apply(step);
    }
    expect_manifold(state, k);
    if (::testing::Test::HasFatalFailure()) return;
  }
  EXPECT_GT(collapses, 80);
}

TEST(ProgressiveMesh, InfluenceRemovalCostIsTheRmsMotionOverThePoses) {
  // P was averaged over c.poses, so ‖s‖²₂,₂ = mean over those poses of ‖G s‖²: posing the vertex
  // before and after each removal and averaging is an independent measurement of the cost.
  const LodCase c = arm_lod_case();
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  int removals = 0;
  for (const Simplification& step : pm->steps) {
    if (step.kind != SimplificationKind::kInfluenceRemoval) continue;
    ++removals;
    double sum = 0;
    for (const as::TransformList& G : c.poses) sum += (posed_point(G, step.after) - posed_point(G, step.before)).squaredNorm();
    EXPECT_NEAR(step.cost, std::sqrt(sum / static_cast<double>(c.poses.size())), 1e-9);
    EXPECT_NEAR(step.after.position.row(3).sum(), 1.0, 1e-12);  // p̲ = 1 kept
    EXPECT_EQ(step.after.influence_count() + 1, step.before.influence_count());
    EXPECT_EQ(std::count(step.after.bones.begin(), step.after.bones.end(), step.target), 0);
  }
  EXPECT_GT(removals, 10);  // the elbow zone has two bones per vertex
}

TEST(ProgressiveMesh, WithoutInfluenceSimplificationOnlyCollapses) {
  const LodCase c = arm_lod_case();
  SimplifyOptions options;
  options.influence_simplification = false;
  auto pm = build_progressive_mesh(c.model, c.metrics, options);
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  for (const Simplification& step : pm->steps) EXPECT_EQ(step.kind, SimplificationKind::kEdgeCollapse);
  EXPECT_EQ(pm->base.vertex_count(), options.min_vertices);
}

TEST(ProgressiveMesh, RefusesWhatItCannotSimplify) {
  LodCase c = pyramid_case(0.5);
  // A third face on edge (0, 1): non-manifold.
  as::AnimationSpaceModel bad = c.model;
  bad.positions.conservativeResize(4, 6);
  bad.positions.col(5) << 0.5, -0.5, 1, 1;
  bad.influences.bones.push_back(0);
  bad.influences.offsets.push_back(6);
  bad.faces.conservativeResize(5, 3);
  bad.faces.row(4) << 1, 0, 5;
  auto r = build_progressive_mesh(bad, c.metrics, {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(r.error().message.find("face 4"), std::string::npos) << r.error().message;

  as::AnimationSpaceModel unused = c.model;
  unused.faces.conservativeResize(2, 3);  // vertex 4 was only on faces 2 and 3
  r = build_progressive_mesh(unused, c.metrics, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("vertex 4"), std::string::npos) << r.error().message;

  as::AnimationSpaceModel no_faces = c.model;
  no_faces.faces.resize(0, 3);
  EXPECT_FALSE(build_progressive_mesh(no_faces, c.metrics, {}).ok());

  const LodCase arm = arm_lod_case();
  r = build_progressive_mesh(c.model, arm.metrics, {});  // 3-bone metrics for a 1-bone model
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("metrics"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace animspace::lod

namespace animspace::lod {
namespace {

// Progress counts collapsed vertices against all that may go (the input less min_vertices),
// never goes back, and ends complete.
TEST(ProgressiveMesh, ReportsCollapsesAsProgress) {
  const testing::LodCase c = testing::flat_sheet_case(6);
  SimplifyOptions options;
  options.min_vertices = 4;
  std::vector<std::pair<int64_t, int64_t>> calls;
  options.progress = [&](std::string_view stage, int64_t done, int64_t total) {
    EXPECT_EQ(stage, "simplification");
    calls.emplace_back(done, total);
  };
  auto pm = build_progressive_mesh(c.model, c.metrics, options);
  ASSERT_TRUE(pm.ok()) << pm.error().message;
  ASSERT_GE(calls.size(), 2u);
  const int64_t collapsible = c.model.vertex_count() - 4;
  EXPECT_EQ(calls.front(), std::make_pair(int64_t{0}, collapsible));
  EXPECT_EQ(calls.back(), std::make_pair(collapsible, collapsible));
  for (size_t k = 1; k < calls.size(); ++k) EXPECT_GE(calls[k].first, calls[k - 1].first);
}

}  // namespace
}  // namespace animspace::lod
