// Levels of detail under a texture atlas (issue #37, Merry 2007 §5.1, §5.3): every level keeps
// the atlas's charts and borders and carries one-to-one UVs. Checked against the input mesh and
// its atlas directly — charts, borders and UVs recomputed here from faces, never from the
// simplifier's own bookkeeping — and, for one-to-one, by testing every pair of a chart's UV
// triangles for overlap.
#include "core/lod/chart_atlas.h"

#include <algorithm>
#include <array>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/atlas/atlas.h"
#include "core/lod/levels.h"
#include "core/lod/lod_io.h"
#include "core/animspace/animspace_io.h"
#include "harness/lod_fixtures.h"

namespace animspace::lod {
namespace {

namespace as = animation_space;

struct AtlasCase {
  testing::LodCase lod;
  ChartAtlas atlas;
};

const AtlasCase& arm_with_atlas() {
  static const AtlasCase c = [] {
    AtlasCase out;
    out.lod = testing::arm_lod_case(25, 12, 24);
    auto built = atlas::build_atlas(out.lod.model, out.lod.metrics, atlas::AtlasOptions{});
    EXPECT_TRUE(built.ok()) << built.error().message;
    out.atlas = ChartAtlas{built->atlas.chart_of_face, built->atlas.uvs};
    return out;
  }();
  return c;
}

const BuiltLevels& arm_levels(bool with_atlas) {
  static const BuiltLevels levels[2] = {[] {
                                          auto b = build_levels(arm_with_atlas().lod.model, arm_with_atlas().lod.metrics);
                                          EXPECT_TRUE(b.ok());
                                          return *b;
                                        }(),
                                        [] {
                                          LevelBuildOptions options;
                                          options.atlas = &arm_with_atlas().atlas;
                                          auto b = build_levels(arm_with_atlas().lod.model,
                                                                arm_with_atlas().lod.metrics, options);
                                          EXPECT_TRUE(b.ok()) << b.error().message;
                                          return *b;
                                        }()};
  return levels[with_atlas ? 1 : 0];
}

// What the input and its atlas say, recomputed from faces: the charts each vertex touches, its UV
// in each, the vertices on a border (touching two or more charts), and each chart's UV orientation.
struct InputCharts {
  std::map<std::pair<int32_t, int32_t>, Eigen::Vector2d> uv;  // (vertex, chart)
  std::vector<std::set<int32_t>> charts_of_vertex;
  std::map<int32_t, double> orientation;  // chart → sign of its faces' UV area
};

double area(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

InputCharts input_charts(const FaceMatrix& F, const ChartAtlas& atlas, int V) {
  InputCharts in;
  in.charts_of_vertex.resize(static_cast<size_t>(V));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const int32_t c = atlas.chart_of_face[static_cast<size_t>(f)];
    for (int k = 0; k < 3; ++k) {
      in.uv[{F(f, k), c}] = atlas.uvs.row(3 * f + k).transpose();
      in.charts_of_vertex[static_cast<size_t>(F(f, k))].insert(c);
    }
    const double a = area(atlas.uvs.row(3 * f).transpose(), atlas.uvs.row(3 * f + 1).transpose(),
                          atlas.uvs.row(3 * f + 2).transpose());
    if (!in.orientation.contains(c)) in.orientation[c] = a > 0 ? 1 : -1;
  }
  return in;
}

// Do two UV triangles overlap in more than a shared edge or corner? Separating axes (the six edge
// normals), with a tolerance so that triangles that only touch are apart.
bool overlap(const std::array<Eigen::Vector2d, 3>& a, const std::array<Eigen::Vector2d, 3>& b) {
  const double tolerance = 1e-12;
  for (const auto* t : {&a, &b}) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d e = (*t)[static_cast<size_t>((k + 1) % 3)] - (*t)[static_cast<size_t>(k)];
      const Eigen::Vector2d n(-e.y(), e.x());
      double a_min = 1e300, a_max = -1e300, b_min = 1e300, b_max = -1e300;
      for (const Eigen::Vector2d& p : a) a_min = std::min(a_min, n.dot(p)), a_max = std::max(a_max, n.dot(p));
      for (const Eigen::Vector2d& p : b) b_min = std::min(b_min, n.dot(p)), b_max = std::max(b_max, n.dot(p));
      const double scale = n.norm();
      if (a_max <= b_min + tolerance * scale || b_max <= a_min + tolerance * scale) return false;
    }
  }
  return true;
}

TEST(ChartAtlasLevels, EveryFaceStaysInItsChartWithItsVerticesUvs) {
  const AtlasCase& c = arm_with_atlas();
  const BuiltLevels& built = arm_levels(true);
  const InputCharts in = input_charts(c.lod.model.faces, c.atlas, c.lod.model.vertex_count());
  ASSERT_GE(built.lods.count(), 3);
  for (int l = 0; l < built.lods.count(); ++l) {
    const LodLevel& level = built.lods.levels[static_cast<size_t>(l)];
    ASSERT_EQ(level.face_ids.size(), static_cast<size_t>(level.model.faces.rows()));
    ASSERT_EQ(level.corner_uvs.rows(), 3 * level.model.faces.rows()) << "level " << l;
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int32_t chart = c.atlas.chart_of_face[static_cast<size_t>(level.face_ids[static_cast<size_t>(f)])];
      for (int k = 0; k < 3; ++k) {
        const int32_t v = level.vertex_ids[static_cast<size_t>(level.model.faces(f, k))];
        // The corner's vertex is a vertex of the face's chart in the input, and its UV there is
        // the one the level carries: a vertex that stays keeps its level-0 UV.
        const auto at = in.uv.find({v, chart});
        ASSERT_NE(at, in.uv.end()) << "level " << l << " face " << f << ": vertex " << v << " not in chart " << chart;
        EXPECT_EQ(level.corner_uvs.row(3 * f + k).transpose(), at->second) << "level " << l << " face " << f;
      }
    }
  }
}

TEST(ChartAtlasLevels, BordersAreOriginalBordersAndCornersNeverMove) {
  const AtlasCase& c = arm_with_atlas();
  const BuiltLevels& built = arm_levels(true);
  const InputCharts in = input_charts(c.lod.model.faces, c.atlas, c.lod.model.vertex_count());
  // Input border edges: edges whose two faces lie in different charts.
  const auto border_edges = [&](const FaceMatrix& F, const std::vector<int32_t>& face_ids,
                                const std::vector<int32_t>& vertex_ids) {
    std::map<std::pair<int32_t, int32_t>, std::vector<int32_t>> charts_of_edge;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      const int32_t chart = c.atlas.chart_of_face[static_cast<size_t>(face_ids[static_cast<size_t>(f)])];
      for (int k = 0; k < 3; ++k) {
        int32_t a = vertex_ids[static_cast<size_t>(F(f, k))], b = vertex_ids[static_cast<size_t>(F(f, (k + 1) % 3))];
        if (a > b) std::swap(a, b);
        charts_of_edge[{a, b}].push_back(chart);
      }
    }
    std::set<std::pair<int32_t, int32_t>> out;
    for (const auto& [edge, charts] : charts_of_edge) {
      if (charts.size() == 2 && charts[0] != charts[1]) out.insert(edge);
    }
    return out;
  };
  const LodLevel& input = built.lods.levels[0];
  const auto input_border = border_edges(input.model.faces, input.face_ids, input.vertex_ids);
  ASSERT_FALSE(input_border.empty());
  std::set<int32_t> input_border_vertices;
  for (const auto& [a, b] : input_border) input_border_vertices.insert({a, b});
  std::vector<int32_t> corners;  // where three or more charts meet
  for (int32_t v = 0; v < c.lod.model.vertex_count(); ++v) {
    if (in.charts_of_vertex[static_cast<size_t>(v)].size() >= 3) corners.push_back(v);
  }
  int border_vertices_removed = 0;
  const LodLevel& coarsest = built.lods.levels.back();
  for (const int32_t v : input_border_vertices) {
    if (!std::binary_search(coarsest.vertex_ids.begin(), coarsest.vertex_ids.end(), v)) ++border_vertices_removed;
  }
  for (int l = 1; l < built.lods.count(); ++l) {
    const LodLevel& level = built.lods.levels[static_cast<size_t>(l)];
    const auto border = border_edges(level.model.faces, level.face_ids, level.vertex_ids);
    EXPECT_FALSE(border.empty()) << "level " << l;
    for (const auto& [a, b] : border) {
      EXPECT_TRUE(input_border_vertices.contains(a)) << "level " << l << ": border vertex " << a << " is not one";
      EXPECT_TRUE(input_border_vertices.contains(b)) << "level " << l << ": border vertex " << b << " is not one";
    }
    for (const int32_t v : corners) {
      EXPECT_TRUE(std::binary_search(level.vertex_ids.begin(), level.vertex_ids.end(), v))
          << "level " << l << " lost vertex " << v << ", where three charts meet";
    }
    // Every chart of the input is still there.
    std::set<int32_t> charts;
    for (const int32_t f : level.face_ids) charts.insert(c.atlas.chart_of_face[static_cast<size_t>(f)]);
    EXPECT_EQ(charts.size(), in.orientation.size()) << "level " << l;
  }
  // The rule is not "borders are frozen": border vertices between corners do go, along the border.
  EXPECT_GT(border_vertices_removed, 0);
}

TEST(ChartAtlasLevels, UvsAreOneToOneInEveryChart) {
  const AtlasCase& c = arm_with_atlas();
  const BuiltLevels& built = arm_levels(true);
  const InputCharts in = input_charts(c.lod.model.faces, c.atlas, c.lod.model.vertex_count());
  for (int l = 0; l < built.lods.count(); ++l) {
    const LodLevel& level = built.lods.levels[static_cast<size_t>(l)];
    std::map<int32_t, std::vector<std::array<Eigen::Vector2d, 3>>> by_chart;
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int32_t chart = c.atlas.chart_of_face[static_cast<size_t>(level.face_ids[static_cast<size_t>(f)])];
      std::array<Eigen::Vector2d, 3> t;
      for (int k = 0; k < 3; ++k) t[static_cast<size_t>(k)] = level.corner_uvs.row(3 * f + k).transpose();
      EXPECT_GT(in.orientation.at(chart) * area(t[0], t[1], t[2]), 0)
          << "level " << l << " face " << f << " (chart " << chart << ") is flipped or degenerate in UV";
      by_chart[chart].push_back(t);
    }
    for (const auto& [chart, triangles] : by_chart) {
      for (size_t i = 0; i < triangles.size(); ++i) {
        for (size_t j = i + 1; j < triangles.size(); ++j) {
          EXPECT_FALSE(overlap(triangles[i], triangles[j]))
              << "level " << l << " chart " << chart << ": triangles " << i << " and " << j << " overlap in UV";
        }
      }
    }
  }
}

TEST(ChartAtlasLevels, WithoutTheAtlasCollapsesCrossCharts) {
  // The constraint is not vacuous on this mesh: the same build without it leaves faces whose
  // corners are vertices of no common chart.
  const AtlasCase& c = arm_with_atlas();
  const BuiltLevels& free = arm_levels(false);
  const InputCharts in = input_charts(c.lod.model.faces, c.atlas, c.lod.model.vertex_count());
  int crossing = 0;
  for (const LodLevel& level : free.lods.levels) {
    ASSERT_EQ(level.corner_uvs.rows(), 0);
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int32_t chart = c.atlas.chart_of_face[static_cast<size_t>(level.face_ids[static_cast<size_t>(f)])];
      for (int k = 0; k < 3; ++k) {
        const int32_t v = level.vertex_ids[static_cast<size_t>(level.model.faces(f, k))];
        if (!in.charts_of_vertex[static_cast<size_t>(v)].contains(chart)) ++crossing;
      }
    }
  }
  EXPECT_GT(crossing, 0);
}

TEST(ChartAtlasLevels, StoredUvsLoadAndFilesWithoutThemStillLoad) {
  const AtlasCase& c = arm_with_atlas();
  const BuiltLevels& built = arm_levels(true);
  container::ModelContainer file;
  as::store(c.lod.model, file);
  store_levels(built.lods, file);
  auto loaded = load_levels(file, c.lod.model, "arm.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_EQ(loaded->count(), built.lods.count());
  for (int l = 1; l < built.lods.count(); ++l) {
    EXPECT_EQ(loaded->levels[static_cast<size_t>(l)].face_ids, built.lods.levels[static_cast<size_t>(l)].face_ids);
    EXPECT_EQ(loaded->levels[static_cast<size_t>(l)].corner_uvs, built.lods.levels[static_cast<size_t>(l)].corner_uvs);
  }

  // A file written before levels had face ids and UVs: the same levels, neither section.
  LodLevels old = built.lods;
  for (LodLevel& level : old.levels) {
    level.face_ids.clear();
    level.corner_uvs.resize(0, 2);
  }
  container::ModelContainer old_file;
  as::store(c.lod.model, old_file);
  store_levels(old, old_file);
  EXPECT_FALSE(old_file.has_section("lod.1.uvs"));
  EXPECT_FALSE(old_file.has_section("lod.1.face_ids"));
  auto old_loaded = load_levels(old_file, c.lod.model, "old.anim");
  ASSERT_TRUE(old_loaded.ok()) << old_loaded.error().message;
  for (int l = 1; l < old_loaded->count(); ++l) {
    EXPECT_EQ(old_loaded->levels[static_cast<size_t>(l)].corner_uvs.rows(), 0);
    EXPECT_TRUE(old_loaded->levels[static_cast<size_t>(l)].face_ids.empty());
    EXPECT_EQ(old_loaded->levels[static_cast<size_t>(l)].model.faces, built.lods.levels[static_cast<size_t>(l)].model.faces);
  }

  // A UV outside the unit square is named by section, row and column.
  const LodLevel& one = built.lods.levels[1];
  container::Float64Matrix bad = Eigen::Map<const container::Float64Matrix>(one.corner_uvs.data(), one.model.faces.rows(), 6);
  bad(2, 3) = 1.5;
  file.set_matrix("lod.1.uvs", bad);
  auto refused = load_levels(file, c.lod.model, "arm.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("arm.anim: section 'lod.1.uvs' row 2 column 3: expected a UV in [0, 1], got 1.5"),
            std::string::npos)
      << refused.error().message;
}

TEST(ChartAtlasLevels, AnAtlasThatDoesNotFitIsRefusedByName) {
  const AtlasCase& c = arm_with_atlas();
  const InputCharts in = input_charts(c.lod.model.faces, c.atlas, c.lod.model.vertex_count());
  // The last corner of a face whose vertex lies inside one chart (so it has other faces there)
  // moves: that vertex now has two UVs in its chart.
  Eigen::Index row = -1;
  for (Eigen::Index f = c.lod.model.faces.rows() - 1; f >= 0 && row < 0; --f) {
    if (in.charts_of_vertex[static_cast<size_t>(c.lod.model.faces(f, 2))].size() == 1) row = 3 * f + 2;
  }
  ASSERT_GE(row, 0);
  ChartAtlas two_uvs = c.atlas;
  two_uvs.uvs(row, 0) += 0.01;
  SimplifyOptions options;
  options.atlas = &two_uvs;
  auto refused = build_progressive_mesh(c.lod.model, c.lod.metrics, options);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("atlas: vertex " + std::to_string(c.lod.model.faces(row / 3, 2)) +
                                         " has two UVs in chart"),
            std::string::npos)
      << refused.error().message;

  ChartAtlas short_charts = c.atlas;
  short_charts.chart_of_face.pop_back();
  options.atlas = &short_charts;
  refused = build_progressive_mesh(c.lod.model, c.lod.metrics, options);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("atlas: chart_of_face: expected " + std::to_string(c.lod.model.faces.rows())),
            std::string::npos)
      << refused.error().message;
}

}  // namespace
}  // namespace animspace::lod
