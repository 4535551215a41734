// The demo's subdivided arm with its atlas (arm-smooth): the thesis's two systems on the bundled
// model, judged with independent computations on the demo arm itself.
#include <map>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "core/atlas/atlas_io.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"

namespace animspace::demo {
namespace {

TEST(DemoSmoothTest, IsTheArmSubdividedOnceWithAnAtlasOfDiscChartsAndLevelsThatKeepThem) {
  auto arm = make_demo_animation_space_container();
  ASSERT_TRUE(arm.ok()) << arm.error().message;
  auto control = animation_space::load(*arm, "arm-animspace");
  ASSERT_TRUE(control.ok()) << control.error().message;
  auto smooth_file = make_demo_smooth_container(*arm);
  ASSERT_TRUE(smooth_file.ok()) << smooth_file.error().message;
  auto smooth = animation_space::load(*smooth_file, "arm-smooth");
  ASSERT_TRUE(smooth.ok()) << smooth.error().message;

  // One Loop step on a closed triangle mesh: a vertex per control vertex and per edge, four
  // triangles per triangle (edges counted here from the control faces).
  std::set<std::pair<int, int>> edges;
  for (Eigen::Index f = 0; f < control->faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int a = control->faces(f, c), b = control->faces(f, (c + 1) % 3);
      edges.insert({std::min(a, b), std::max(a, b)});
    }
  }
  EXPECT_EQ(smooth->vertex_count(), control->vertex_count() + static_cast<int>(edges.size()));
  EXPECT_EQ(smooth->faces.rows(), 4 * control->faces.rows());
  EXPECT_TRUE(smooth->has_tangents()) << "limit normals";

  // The atlas covers every face, its UVs in the unit square, every chart a disc by Euler's count.
  auto atlas = atlas::load_atlas(*smooth_file, smooth->faces.rows(), "arm-smooth");
  ASSERT_TRUE(atlas.ok()) << atlas.error().message;
  ASSERT_TRUE(atlas->has_value()) << "the demo's smooth arm carries its atlas";
  const atlas::Atlas& a = **atlas;
  ASSERT_GE(a.chart_count, 2);
  EXPECT_GE(a.uvs.minCoeff(), 0.0);
  EXPECT_LE(a.uvs.maxCoeff(), 1.0);
  for (int chart = 0; chart < a.chart_count; ++chart) {
    std::set<int> vertices;
    std::set<std::pair<int, int>> chart_edges;
    long faces = 0;
    for (Eigen::Index f = 0; f < smooth->faces.rows(); ++f) {
      if (a.chart_of_face[static_cast<size_t>(f)] != chart) continue;
      ++faces;
      for (int c = 0; c < 3; ++c) {
        const int u = smooth->faces(f, c), w = smooth->faces(f, (c + 1) % 3);
        vertices.insert(u);
        chart_edges.insert({std::min(u, w), std::max(u, w)});
      }
    }
    EXPECT_EQ(static_cast<long>(vertices.size()) - static_cast<long>(chart_edges.size()) + faces, 1)
        << "chart " << chart << " is not a disc";
  }

  // Its levels of detail keep the charts (issue #37, §5.1): every level carries UVs, each corner
  // the atlas's UV of its vertex in the chart of the face it came from.
  auto levels = lod::load_levels(*smooth_file, *smooth, "arm-smooth");
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  ASSERT_GE(levels->count(), 3);
  std::map<std::pair<int, int>, Eigen::RowVector2d> uv;  // (vertex, chart)
  for (Eigen::Index f = 0; f < smooth->faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) uv[{smooth->faces(f, c), a.chart_of_face[static_cast<size_t>(f)]}] = a.uvs.row(3 * f + c);
  }
  for (int l = 1; l < levels->count(); ++l) {
    const lod::LodLevel& level = levels->levels[static_cast<size_t>(l)];
    ASSERT_EQ(level.corner_uvs.rows(), 3 * level.model.faces.rows()) << "level " << l;
    ASSERT_EQ(level.face_ids.size(), static_cast<size_t>(level.model.faces.rows()));
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int chart = a.chart_of_face[static_cast<size_t>(level.face_ids[static_cast<size_t>(f)])];
      for (int c = 0; c < 3; ++c) {
        const auto at = uv.find({level.vertex_ids[static_cast<size_t>(level.model.faces(f, c))], chart});
        ASSERT_NE(at, uv.end()) << "level " << l << " face " << f << " corner " << c << " leaves its chart";
        EXPECT_EQ(level.corner_uvs.row(3 * f + c), at->second) << "level " << l << " face " << f;
      }
    }
  }
}

}  // namespace
}  // namespace animspace::demo
