// `animspace atlas` end to end: the command line adds the atlas section to a model file, the file
// still loads as a model, `export-lod --level 0` writes its UVs, `build-lod` keeps its charts and
// `export-lod` writes every level's UVs, and bad input is refused naming the flag or the file.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "harness/build_tree.h"
#include "tests/support/cli_run.h"
#include "tests/support/gltf_posing.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

testing::CliRun cli(const std::string& arguments, const testing::TempDir& dir) {
  return testing::run_command(harness::program_path("animspace").string() + " " + arguments, dir / "stderr.txt");
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

// The faces of an OBJ as the UVs of their three corners (vt), in file order.
std::vector<std::array<float, 6>> obj_face_uvs(const std::filesystem::path& path) {
  std::ifstream obj(path);
  std::string line;
  std::vector<std::array<float, 2>> vt;
  std::vector<std::array<float, 6>> faces;
  while (std::getline(obj, line)) {
    std::istringstream fields(line.substr(line.find(' ') + 1));
    if (line.rfind("vt ", 0) == 0) {
      std::array<float, 2> uv{};
      fields >> uv[0] >> uv[1];
      vt.push_back(uv);
    } else if (line.rfind("f ", 0) == 0) {
      std::array<float, 6> face{};
      std::string corner;
      for (int k = 0; k < 3 && fields >> corner; ++k) {
        const auto slash = corner.find('/');
        const long t = slash == std::string::npos ? 0 : std::strtol(corner.c_str() + slash + 1, nullptr, 10);
        if (t < 1 || t > static_cast<long>(vt.size())) return {};  // a corner without its vt
        face[static_cast<size_t>(2 * k)] = vt[static_cast<size_t>(t - 1)][0];
        face[static_cast<size_t>(2 * k + 1)] = vt[static_cast<size_t>(t - 1)][1];
      }
      faces.push_back(face);
    }
  }
  return faces;
}

TEST(CliAtlas, BuildLodKeepsTheChartsAndExportLodWritesEveryLevelsUvs) {
  testing::TempDir dir;
  auto demo = demo::make_demo_animation_space_container();
  ASSERT_TRUE(demo.ok());
  ASSERT_TRUE(container::write_file(dir / "arm.anim", *demo).ok());
  ASSERT_EQ(cli("atlas " + (dir / "arm.anim").string() + " -o " + (dir / "arm-atlas.anim").string(), dir).exit_code, 0);
  const auto built = cli("--json build-lod " + (dir / "arm-atlas.anim").string() + " -o " +
                             (dir / "arm-lod.anim").string(), dir);
  const nlohmann::json report = testing::json_of(built);
  ASSERT_TRUE(report.contains("chart_borders")) << built.out << built.err;
  EXPECT_TRUE(report["chart_borders"].get<bool>());

  auto file = container::read_file(dir / "arm-lod.anim");
  ASSERT_TRUE(file.ok());
  auto model = animation_space::load(*file, "arm-lod.anim");
  ASSERT_TRUE(model.ok()) << model.error().message;
  auto levels = lod::load_levels(*file, *model, "arm-lod.anim");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  ASSERT_GE(levels->count(), 3);
  auto charts = file->int_matrix(container::sections::kAtlasChartIds, 1);
  auto uvs = file->double_matrix(container::sections::kAtlasUvs, 6);
  ASSERT_TRUE(charts.ok() && uvs.ok());
  std::map<std::pair<int, int>, std::array<float, 2>> uv;  // (vertex, chart) from the atlas sections
  for (Eigen::Index f = 0; f < model->faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      uv[{model->faces(f, k), (*charts)(f, 0)}] = {static_cast<float>((*uvs)(f, 2 * k)),
                                                   static_cast<float>((*uvs)(f, 2 * k + 1))};
    }
  }
  // Every level's OBJ: one vt per corner, and the faces' corner UVs (in the file's own face order,
  // which the vertex-cache optimisation changes) those of the level's faces in their charts.
  for (int l = 0; l < levels->count(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    const auto obj = dir / ("level" + std::to_string(l) + ".obj");
    const auto exported = cli("--json export-lod " + (dir / "arm-lod.anim").string() + " --level " + std::to_string(l) +
                                  " -o " + obj.string(), dir);
    ASSERT_EQ(exported.exit_code, 0) << exported.err;
    EXPECT_TRUE(testing::json_of(exported)["texture_coordinates"].get<bool>());
    const lod::LodLevel& level = levels->levels[static_cast<size_t>(l)];
    std::vector<std::array<float, 6>> want;
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int chart = (*charts)(level.face_ids[static_cast<size_t>(f)], 0);
      std::array<float, 6> face{};
      for (int k = 0; k < 3; ++k) {
        const auto at = uv.find({level.vertex_ids[static_cast<size_t>(level.model.faces(f, k))], chart});
        ASSERT_NE(at, uv.end()) << "face " << f << " corner " << k << " is no vertex of its chart";
        face[static_cast<size_t>(2 * k)] = at->second[0];
        face[static_cast<size_t>(2 * k + 1)] = at->second[1];
      }
      want.push_back(face);
    }
    std::vector<std::array<float, 6>> got = obj_face_uvs(obj);
    ASSERT_EQ(got.size(), want.size());
    // A face may start at another corner after reordering: compare each from its smallest corner.
    const auto canonical = [](std::array<float, 6> face) {
      std::array<float, 6> best = face;
      for (int r = 1; r < 3; ++r) {
        std::rotate(face.begin(), face.begin() + 2, face.end());
        best = std::min(best, face);
      }
      return best;
    };
    for (auto* faces : {&got, &want}) {
      for (auto& face : *faces) face = canonical(face);
      std::sort(faces->begin(), faces->end());
    }
    for (size_t f = 0; f < got.size(); ++f) {
      for (size_t c = 0; c < 6; ++c) ASSERT_NEAR(got[f][c], want[f][c], 1e-6) << "face " << f;
    }
  }

  // export-rig at a coarser level: TEXCOORD_0 per corner, in face order, the level's UVs in their
  // charts (glTF's v runs down: the file holds 1 − v).
  const int rig_level = levels->count() / 2;
  const auto glb = dir / "rig.glb";
  const auto rig = cli("--json export-rig " + (dir / "arm-lod.anim").string() + " --level " +
                           std::to_string(rig_level) + " -o " + glb.string(), dir);
  EXPECT_TRUE(testing::json_of(rig).at("texture_coordinates").get<bool>());
  {
    std::ifstream in(glb, std::ios::binary);
    const testing::LoadedGltf loaded =
        testing::load_gltf(std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()), true);
    ASSERT_TRUE(loaded.ok) << loaded.error;
    const tinygltf::Primitive& primitive = loaded.model.meshes.at(0).primitives.at(0);
    ASSERT_EQ(primitive.attributes.count("TEXCOORD_0"), 1u);
    const std::vector<uint32_t> indices = testing::accessor_values<uint32_t>(
        loaded.model, primitive.indices, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR);
    const std::vector<float> texcoords = testing::accessor_values<float>(
        loaded.model, primitive.attributes.at("TEXCOORD_0"), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2);
    const lod::LodLevel& level = levels->levels[static_cast<size_t>(rig_level)];
    ASSERT_EQ(indices.size(), static_cast<size_t>(3 * level.model.faces.rows()));
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int chart = (*charts)(level.face_ids[static_cast<size_t>(f)], 0);
      for (int k = 0; k < 3; ++k) {
        const auto at = uv.find({level.vertex_ids[static_cast<size_t>(level.model.faces(f, k))], chart});
        ASSERT_NE(at, uv.end());
        const uint32_t vertex = indices[static_cast<size_t>(3 * f + k)];
        ASSERT_NEAR(texcoords[2 * vertex], at->second[0], 1e-6) << "face " << f << " corner " << k;
        ASSERT_NEAR(1.0f - texcoords[2 * vertex + 1], at->second[1], 1e-6) << "face " << f << " corner " << k;
      }
    }
  }

  // A new atlas makes the levels' UVs stale: `atlas` drops them, and export-lod writes none.
  const auto again = cli("--json atlas " + (dir / "arm-lod.anim").string() + " --charts 5 -o " +
                             (dir / "re-atlas.anim").string(), dir);
  const nlohmann::json re = testing::json_of(again);
  ASSERT_TRUE(re.contains("dropped_level_uvs")) << again.out << again.err;
  EXPECT_EQ(re["dropped_level_uvs"].get<int>(), levels->count() - 1);
  auto re_file = container::read_file(dir / "re-atlas.anim");
  ASSERT_TRUE(re_file.ok());
  EXPECT_FALSE(re_file->has_section("lod.1.uvs"));
  const auto stale = cli("--json export-lod " + (dir / "re-atlas.anim").string() + " --level 1 -o " +
                             (dir / "stale.obj").string(), dir);
  ASSERT_EQ(stale.exit_code, 0) << stale.err;
  EXPECT_FALSE(testing::json_of(stale)["texture_coordinates"].get<bool>());
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
