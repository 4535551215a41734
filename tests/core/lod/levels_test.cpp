// Discrete levels, eq. 7.2 worked by hand, geomorphs (§7.3) and their storage.
#include "core/lod/levels.h"

#include <numbers>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/lod/lod_io.h"
#include "core/lod/simplify.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;
using testing::arm_lod_case;
using testing::LodCase;

PointMatrix pose(const as::AnimationSpaceModel& model, const as::TransformList& G) {
  PointMatrix out;
  as::evaluate(model, G, out);
  return out;
}

LodLevels arm_levels(const LodCase& c) {
  auto pm = build_progressive_mesh(c.model, c.metrics, {});
  EXPECT_TRUE(pm.ok());
  return make_levels(*pm);
}

TEST(LodLevels, HalveTheInfluencesWithNonDecreasingError) {
  const LodCase c = arm_lod_case();
  const LodLevels lods = arm_levels(c);
  ASSERT_GE(lods.count(), 5);
  // Level 0 is the input itself.
  EXPECT_EQ(lods.levels[0].model.positions, c.model.positions);
  EXPECT_EQ(lods.levels[0].model.faces, c.model.faces);
  EXPECT_EQ(lods.levels[0].epsilon, 0);
  for (int l = 1; l < lods.count(); ++l) {
    const LodLevel& fine = lods.levels[static_cast<size_t>(l - 1)];
    const LodLevel& level = lods.levels[static_cast<size_t>(l)];
    EXPECT_GE(level.epsilon, fine.epsilon) << "level " << l;
    EXPECT_GT(level.step_count, fine.step_count);
    if (l + 1 < lods.count()) {  // the last level is the base mesh, wherever it falls
      EXPECT_LE(level.model.influences.influence_count(), fine.model.influences.influence_count() / 2) << l;
    }
    EXPECT_TRUE(as::validate(level.model).ok()) << "level " << l;  // p̲ = 1 everywhere
    for (size_t k = 1; k < level.vertex_ids.size(); ++k) EXPECT_LT(level.vertex_ids[k - 1], level.vertex_ids[k]);
  }
}

// Geomorphs run from each level to the next: on the progressive mesh's own levels, and on the
// served ones, whose vertices are placed and whose influences differ from the coarser level's.
class GeomorphTest : public ::testing::TestWithParam<bool> {};

TEST_P(GeomorphTest, RunsFromOneLevelToTheNext) {
  const LodCase c = arm_lod_case();
  LodLevels lods;
  if (GetParam()) {
    auto built = build_levels(c.model, c.metrics);
    ASSERT_TRUE(built.ok()) << built.error().message;
    lods = std::move(built->lods);
  } else {
    lods = arm_levels(c);
  }
  ASSERT_GE(lods.count(), 3);
  const as::TransformList& G = c.poses[7];
  for (int l = 0; l + 1 < lods.count(); ++l) {
    const LodLevel& fine = lods.levels[static_cast<size_t>(l)];
    const PointMatrix fine_points = pose(fine.model, G);
    const PointMatrix coarse_points = pose(lods.levels[static_cast<size_t>(l) + 1].model, G);
    const PointMatrix at0 = pose(geomorphed_model(lods, l, 0), G);
    const PointMatrix at1 = pose(geomorphed_model(lods, l, 1), G);
    const PointMatrix half = pose(geomorphed_model(lods, l, 0.5), G);
    for (int v = 0; v < fine.model.vertex_count(); ++v) {
      const int target = fine.coarser_vertex[static_cast<size_t>(v)];
      EXPECT_LT((at0.row(v) - fine_points.row(v)).norm(), 1e-5) << "level " << l << " vertex " << v;
      EXPECT_LT((at1.row(v) - coarse_points.row(target)).norm(), 1e-5) << "level " << l << " vertex " << v;
      // Linear in t: the midpoint of the two ends (G is linear in p).
      EXPECT_LT((half.row(v) - 0.5f * (fine_points.row(v) + coarse_points.row(target))).norm(), 1e-5);
    }
    const Geomorph morph = geomorph(lods, l);
    for (int v = 0; v < fine.model.vertex_count(); ++v) {
      double weight = 0;
      for (int i = morph.aligned.begin(v); i < morph.aligned.end(v); ++i) weight += morph.delta(3, i);
      EXPECT_NEAR(weight, 0, 1e-9);  // Δp is a vector
    }
  }
}

INSTANTIATE_TEST_SUITE_P(LodLevels, GeomorphTest, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& param) {
                           return param.param ? "ServedLevels" : "ProgressiveMeshLevels";
                         });

TEST(LodSelection, ToleratedErrorIsEquation72ByHand) {
  // p = 1.5 px, w = 1000 px, 2θ = 60° (sin θ = 1/2), d = 10: ε = 2·1.5·10·0.5/1000 = 0.015.
  PixelTolerance view;
  view.tolerance_px = 1.5;
  view.viewport_width_px = 1000;
  view.horizontal_fov_rad = std::numbers::pi / 3;
  view.distance = 12;  // a sphere of radius 2: d = 10
  auto e = tolerated_error(view, 2);
  ASSERT_TRUE(e.ok());
  EXPECT_NEAR(*e, 0.015, 1e-15);

  LodLevels lods;
  for (const double error : {0.0, 0.01, 0.02, 0.04}) {
    LodLevel level;
    level.epsilon = error;
    lods.levels.push_back(level);
  }
  EXPECT_DOUBLE_EQ(select_level(lods, *e), 1.5);  // halfway between ε¹ = 0.01 and ε² = 0.02
  EXPECT_DOUBLE_EQ(select_level(lods, 0), 0);
  EXPECT_DOUBLE_EQ(select_level(lods, 0.005), 0.5);
  EXPECT_DOUBLE_EQ(select_level(lods, 0.04), 3);
  EXPECT_DOUBLE_EQ(select_level(lods, 7), 3);
  lods.levels[2].epsilon = 0.01;  // equal errors: the coarser level wins
  EXPECT_DOUBLE_EQ(select_level(lods, 0.01), 2);

  // Each field is checked, and named as the API names it, with the value as given.
  for (const auto& [message, broken] :
       std::vector<std::pair<std::string, PixelTolerance>>{{"tolerance_px: expected a finite value > 0, got 0",
                                                            [&] {
                                                              PixelTolerance v = view;
                                                              v.tolerance_px = 0;
                                                              return v;
                                                            }()},
                                                           {"viewport_width_px: expected a finite value > 0, got -4",
                                                            [&] {
                                                              PixelTolerance v = view;
                                                              v.viewport_width_px = -4;
                                                              return v;
                                                            }()},
                                                           {"horizontal_fov_rad: expected a value in (0, π), got 4",
                                                            [&] {
                                                              PixelTolerance v = view;
                                                              v.horizontal_fov_rad = 4;
                                                              return v;
                                                            }()},
                                                           {"distance: expected a finite value > 0, got nan", [&] {
                                                              PixelTolerance v = view;
                                                              v.distance = std::nan("");
                                                              return v;
                                                            }()}}) {
    auto r = tolerated_error(broken, 2);
    ASSERT_FALSE(r.ok()) << message;
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(r.error().message, message);
    EXPECT_EQ(validate(broken).error().message, message);
  }
  // Inside the sphere: nothing tolerated, but a bad view is refused all the same.
  view.distance = 1.5;
  EXPECT_EQ(*tolerated_error(view, 2), 0.0);
  view.tolerance_px = -1;
  EXPECT_FALSE(tolerated_error(view, 2).ok());
}

TEST(LodIo, LevelsRoundTripThroughTheContainer) {
  const LodCase c = arm_lod_case();
  const LodLevels lods = arm_levels(c);
  container::ModelContainer out;
  as::store(c.model, out);
  store_levels(lods, out);
  auto parsed = container::parse(container::serialize(out), "arm.anim");
  ASSERT_TRUE(parsed.ok());
  auto model = as::load(*parsed, "arm.anim");
  ASSERT_TRUE(model.ok());
  auto loaded = load_levels(*parsed, *model, "arm.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_EQ(loaded->count(), lods.count());
  for (int l = 0; l < lods.count(); ++l) {
    const LodLevel& a = lods.levels[static_cast<size_t>(l)];
    const LodLevel& b = loaded->levels[static_cast<size_t>(l)];
    EXPECT_EQ(a.epsilon, b.epsilon);
    EXPECT_EQ(a.vertex_ids, b.vertex_ids);
    EXPECT_EQ(a.coarser_vertex, b.coarser_vertex);
    EXPECT_EQ(a.model.positions, b.model.positions);
    EXPECT_EQ(a.model.influences.bones, b.model.influences.bones);
    EXPECT_EQ(a.model.faces, b.model.faces);
  }
  // A model without levels has one: itself.
  container::ModelContainer plain;
  as::store(c.model, plain);
  auto single = load_levels(plain, c.model, "plain.anim");
  ASSERT_TRUE(single.ok());
  EXPECT_EQ(single->count(), 1);
}

TEST(LodIo, RefusesBrokenLevels) {
  const LodCase c = arm_lod_case();
  const LodLevels lods = arm_levels(c);
  const auto stored = [&] {
    container::ModelContainer out;
    as::store(c.model, out);
    store_levels(lods, out);
    return out;
  };
  {
    container::ModelContainer out = stored();
    container::Float64Matrix errors = out.double_matrix(sections::kErrors, 1).value();
    errors(2, 0) = errors(1, 0) / 2 - 1;  // decreasing
    out.set_matrix(sections::kErrors, errors);
    auto r = load_levels(out, c.model, "m.anim");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("lod.errors' row 2"), std::string::npos) << r.error().message;
  }
  {
    container::ModelContainer out = stored();
    container::Int32Matrix ids = out.int_matrix("lod.1.vertex_ids", 1).value();
    ids(0, 0) = c.model.vertex_count();
    out.set_matrix("lod.1.vertex_ids", ids);
    auto r = load_levels(out, c.model, "m.anim");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("lod.1.vertex_ids' row 0"), std::string::npos) << r.error().message;
  }
  {
    container::ModelContainer out = stored();
    container::Int32Matrix coarser = out.int_matrix("lod.0.coarser_vertex", 1).value();
    coarser(3, 0) = -1;
    out.set_matrix("lod.0.coarser_vertex", coarser);
    auto r = load_levels(out, c.model, "m.anim");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("lod.0.coarser_vertex' row 3"), std::string::npos) << r.error().message;
  }
  {
    container::ModelContainer out = stored();
    container::Float64Matrix positions = out.double_matrix("lod.1.positions", 4).value();
    positions(0, 3) += 0.5;  // p̲ ≠ 1
    out.set_matrix("lod.1.positions", positions);
    auto r = load_levels(out, c.model, "m.anim");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("level 1"), std::string::npos) << r.error().message;
  }
}

}  // namespace
}  // namespace animspace::lod
