// `animspace build-lod` and `animspace export-lod` end to end: the command line builds levels into
// a model file, and the mesh it exports is the core's level posed, point for point.
#include <algorithm>
#include <array>
#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "harness/build_tree.h"
#include "tests/support/cli_run.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

int run(const std::string& arguments) {
  const std::string command = harness::program_path("animspace").string() + " " + arguments + " > /dev/null 2>&1";
  return std::system(command.c_str());
}

std::vector<std::array<float, 3>> sorted_rows(const PointMatrix& points) {
  std::vector<std::array<float, 3>> rows;
  for (Eigen::Index i = 0; i < points.rows(); ++i) rows.push_back({points(i, 0), points(i, 1), points(i, 2)});
  std::sort(rows.begin(), rows.end());
  return rows;
}

TEST(CliLod, BuildsLevelsAndExportsTheCoresLevel) {
  testing::TempDir dir;
  // The demo's animation-space arm, without its levels: build-lod must add them.
  auto demo = demo::make_demo_animation_space_container();
  ASSERT_TRUE(demo.ok());
  container::ModelContainer input;
  input.metadata() = demo->metadata();
  input.metadata().erase("lod_levels");
  auto model = animation_space::load(*demo, "demo");
  ASSERT_TRUE(model.ok());
  animation_space::store(*model, input);
  auto metrics = animation_space::load_metrics(*demo, model->bone_count(), "demo");
  ASSERT_TRUE(metrics.ok());
  animation_space::store_metrics(*metrics, input);
  ASSERT_FALSE(input.has_section(lod::sections::kErrors));
  ASSERT_TRUE(container::write_file(dir / "arm.anim", input).ok());

  ASSERT_EQ(run("build-lod " + (dir / "arm.anim").string() + " --max-levels 5 -o " + (dir / "arm-lod.anim").string()),
            0);
  auto built = container::read_file(dir / "arm-lod.anim");
  ASSERT_TRUE(built.ok());
  auto levels = lod::load_levels(*built, *model, "arm-lod.anim");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  ASSERT_EQ(levels->count(), 5);

  ASSERT_EQ(run("export-lod " + (dir / "arm-lod.anim").string() + " --level 3 -o " + (dir / "l3.obj").string()), 0);
  auto mesh = mesh_io::read_triangle_mesh(dir / "l3.obj");
  ASSERT_TRUE(mesh.ok());
  const lod::LodLevel& level = levels->levels[3];
  PointMatrix expected;
  animation_space::evaluate(level.model, model->skeleton.rest, expected);
  EXPECT_EQ(mesh->F.rows(), level.model.faces.rows());
  EXPECT_EQ(sorted_rows(mesh->V), sorted_rows(expected));  // reordered for the vertex cache, same points

  // Placement moves vertices and nothing else: with edge collapses only, placed and unplaced
  // levels share topology and influences. The default then simplifies each placed level's
  // influences: same vertices and faces, no more influences than edge collapses alone.
  const auto build = [&](const std::string& flags, const std::string& name) {
    EXPECT_EQ(
        run("build-lod " + (dir / "arm.anim").string() + " --max-levels 5 " + flags + " -o " + (dir / name).string()),
        0);
    auto file = container::read_file(dir / name);
    EXPECT_TRUE(file.ok());
    return *file;
  };
  const container::ModelContainer collapses_file = build("--no-influence-simplification", "arm-collapses.anim");
  const container::ModelContainer unplaced_file =
      build("--no-influence-simplification --no-placement", "arm-unplaced.anim");
  EXPECT_EQ(built->metadata().at("lod.placement"), "fitted");
  EXPECT_EQ(unplaced_file.metadata().at("lod.placement"), "none");
  EXPECT_EQ(collapses_file.metadata().at("lod.influence_simplification"), "false");
  EXPECT_NE(built->metadata().at("lod.influence_simplification").find("after placement"), std::string::npos);
  auto collapses = lod::load_levels(collapses_file, *model, "arm-collapses.anim");
  auto unplaced = lod::load_levels(unplaced_file, *model, "arm-unplaced.anim");
  ASSERT_TRUE(collapses.ok()) << collapses.error().message;
  ASSERT_TRUE(unplaced.ok()) << unplaced.error().message;
  ASSERT_EQ(unplaced->count(), levels->count());
  ASSERT_EQ(collapses->count(), levels->count());
  bool moved = false;
  for (int l = 1; l < levels->count(); ++l) {
    const lod::LodLevel& a = collapses->levels[static_cast<size_t>(l)];
    const lod::LodLevel& b = unplaced->levels[static_cast<size_t>(l)];
    const lod::LodLevel& served = levels->levels[static_cast<size_t>(l)];
    EXPECT_EQ(a.vertex_ids, b.vertex_ids) << "level " << l;
    EXPECT_EQ(a.model.faces, b.model.faces) << "level " << l;
    EXPECT_EQ(a.model.influences.bones, b.model.influences.bones) << "level " << l;
    moved = moved || !a.model.positions.isApprox(b.model.positions, 1e-9);
    EXPECT_EQ(served.vertex_ids, a.vertex_ids) << "level " << l;
    EXPECT_EQ(served.model.faces, a.model.faces) << "level " << l;
    EXPECT_LE(served.model.influences.influence_count(), a.model.influences.influence_count()) << "level " << l;
  }
  EXPECT_TRUE(moved);

  // --json reports each level's trade-off: its influences and RMS error beside the same level with
  // edge collapses only, within the exchange rule (x = 1 by default), and the influences are the
  // file's.
  const nlohmann::json report = testing::json_of(
      testing::run_command(harness::program_path("animspace").string() + " --json build-lod " + (dir / "arm.anim").string() +
                               " --max-levels 5 -o " + (dir / "arm-report.anim").string(),
                           dir / "report.err"));
  ASSERT_EQ(report["levels"].size(), static_cast<size_t>(levels->count()));
  for (int l = 1; l < levels->count(); ++l) {
    const nlohmann::json& row = report["levels"][static_cast<size_t>(l)];
    const double influences = row["influences"].get<double>();
    const double before = row["collapses_only"]["influences"].get<double>();
    EXPECT_EQ(row["influences"].get<int>(), levels->levels[static_cast<size_t>(l)].model.influences.influence_count());
    EXPECT_LE(influences, before) << "level " << l;
    EXPECT_LE(row["rms_error"].get<double>(),
              (1 + (before - influences) / before) * row["collapses_only"]["rms_error"].get<double>() * (1 + 1e-9))
        << "level " << l;
    EXPECT_LE(row["rms_error"].get<double>(), row["epsilon"].get<double>() * (1 + 1e-12)) << "level " << l;
  }

  // Refusals: a level that does not exist, a model without metrics and no --sample-poses.
  EXPECT_NE(run("export-lod " + (dir / "arm-lod.anim").string() + " --level 9 -o " + (dir / "x.obj").string()), 0);
  container::ModelContainer bare;
  animation_space::store(*model, bare);
  ASSERT_TRUE(container::write_file(dir / "bare.anim", bare).ok());
  EXPECT_NE(run("build-lod " + (dir / "bare.anim").string() + " -o " + (dir / "y.anim").string()), 0);
  EXPECT_EQ(run("build-lod " + (dir / "bare.anim").string() + " --sample-poses 50 --max-levels 3 -o " +
                (dir / "y.anim").string()),
            0);
}

}  // namespace
}  // namespace animspace
