// `animspace atlas` end to end: the command line adds the atlas section to a model file, the file
// still loads as a model, `export-lod --level 0` writes its UVs, and bad input is refused naming
// the flag or the file.
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "tests/support/cli_run.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

testing::CliRun cli(const std::string& arguments, const testing::TempDir& dir) {
  return testing::run_command(std::string(ANIMSPACE_CLI_PATH) + " " + arguments, dir / "stderr.txt");
}

TEST(CliAtlas, AddsTheAtlasSectionAndExportLodWritesItsUvs) {
  testing::TempDir dir;
  auto demo = demo::make_demo_animation_space_container();  // the arm, with stored metrics
  ASSERT_TRUE(demo.ok());
  ASSERT_TRUE(container::write_file(dir / "arm.anim", *demo).ok());

  const auto run = cli("--json atlas " + (dir / "arm.anim").string() + " -o " + (dir / "arm-atlas.anim").string(), dir);
  const nlohmann::json report = testing::json_of(run);
  ASSERT_TRUE(report.contains("charts")) << run.out;
  EXPECT_GE(report["l2_stretch"].get<double>(), 1.0);  // normalised stretch is at least 1
  EXPECT_GT(report["utilisation"].get<double>(), 0.0);
  EXPECT_LE(report["utilisation"].get<double>(), 1.0);

  auto file = container::read_file(dir / "arm-atlas.anim");
  ASSERT_TRUE(file.ok());
  auto model = animation_space::load(*file, "arm-atlas.anim");
  ASSERT_TRUE(model.ok()) << model.error().message;
  const long F = model->faces.rows();
  auto ids = file->int_matrix(container::sections::kAtlasChartIds, 1);
  auto uvs = file->double_matrix(container::sections::kAtlasUvs, 6);
  ASSERT_TRUE(ids.ok() && uvs.ok());
  EXPECT_EQ(ids->rows(), F);
  EXPECT_EQ(uvs->rows(), F);
  EXPECT_EQ(ids->maxCoeff() + 1, report["charts"].get<int>());
  EXPECT_GE(uvs->minCoeff(), 0.0);
  EXPECT_LE(uvs->maxCoeff(), 1.0);
  EXPECT_EQ(file->metadata_value("atlas.metric"), "poses");

  const auto exported = cli("export-lod " + (dir / "arm-atlas.anim").string() + " --level 0 -o " +
                                (dir / "arm.obj").string(), dir);
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  std::ifstream obj(dir / "arm.obj");
  std::string line;
  long vt = 0, faces = 0, corners_with_vt = 0;
  while (std::getline(obj, line)) {
    if (line.rfind("vt ", 0) == 0) ++vt;
    if (line.rfind("f ", 0) == 0) {
      ++faces;
      std::istringstream fields(line.substr(2));
      std::string corner;
      while (fields >> corner) {
        const auto slash = corner.find('/');
        corners_with_vt += slash != std::string::npos && slash + 1 < corner.size() && corner[slash + 1] != '/';
      }
    }
  }
  EXPECT_EQ(faces, F);
  EXPECT_GE(vt, model->vertex_count());  // seams add vertices, never remove one
  EXPECT_EQ(corners_with_vt, 3 * F);

  // --rest-pose: the same command, the rest pose's stretch.
  const auto rest = cli("atlas " + (dir / "arm.anim").string() + " --rest-pose -o " + (dir / "rest.anim").string(), dir);
  ASSERT_EQ(rest.exit_code, 0) << rest.err;
  auto rest_file = container::read_file(dir / "rest.anim");
  ASSERT_TRUE(rest_file.ok());
  EXPECT_EQ(rest_file->metadata_value("atlas.metric"), "rest_pose");
}

TEST(CliAtlas, RefusalsNameTheFlagOrTheFile) {
  testing::TempDir dir;
  auto demo = demo::make_demo_animation_space_container();
  ASSERT_TRUE(demo.ok());
  ASSERT_TRUE(container::write_file(dir / "arm.anim", *demo).ok());
  const auto missing = cli("atlas " + (dir / "missing.anim").string() + " -o " + (dir / "x.anim").string(), dir);
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.err.find("missing.anim"), std::string::npos) << missing.err;
  const auto charts = cli("atlas " + (dir / "arm.anim").string() + " --charts 0 -o " + (dir / "x.anim").string(), dir);
  EXPECT_NE(charts.exit_code, 0);
  EXPECT_NE(charts.err.find("--charts"), std::string::npos) << charts.err;

  // A model without stored metrics needs --sample-poses (or --rest-pose), and says so.
  auto model = animation_space::load(*demo, "demo");
  ASSERT_TRUE(model.ok());
  container::ModelContainer bare;
  animation_space::store(*model, bare);
  ASSERT_TRUE(container::write_file(dir / "bare.anim", bare).ok());
  const auto bare_run = cli("atlas " + (dir / "bare.anim").string() + " -o " + (dir / "x.anim").string(), dir);
  EXPECT_NE(bare_run.exit_code, 0);
  EXPECT_NE(bare_run.err.find("--sample-poses"), std::string::npos) << bare_run.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.anim"));
  const auto sampled = cli("atlas " + (dir / "bare.anim").string() + " --sample-poses 50 -o " +
                               (dir / "x.anim").string(), dir);
  EXPECT_EQ(sampled.exit_code, 0) << sampled.err;
}

}  // namespace
}  // namespace animspace
