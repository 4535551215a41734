// core/atlas: stretch against analytic values, flattening of developable patches, the atlas's
// one-to-one and disc invariants checked by brute force, and pose-aware flattening against the
// rest-pose one judged by posing the mesh.
#include "core/atlas/atlas.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/animspace/animspace_io.h"
#include "tests/support/articulated_tube.h"

namespace animspace::atlas {
namespace {

namespace as = animation_space;

// A one-bone (rigid) animation-space model of a mesh: p_0 = (v, 1).
as::AnimationSpaceModel rigid_model(const PointMatrix& points, const FaceMatrix& faces) {
  as::AnimationSpaceModel m;
  m.skeleton.parents = {-1};
  m.skeleton.rest = {Eigen::Matrix4d::Identity()};
  m.faces = faces;
  const auto V = static_cast<int>(points.rows());
  m.influences.offsets.resize(static_cast<size_t>(V) + 1);
  m.positions.resize(4, V);
  for (int v = 0; v < V; ++v) {
    m.influences.offsets[static_cast<size_t>(v) + 1] = v + 1;
    m.influences.bones.push_back(0);
    m.positions.col(v) << points.row(v).cast<double>().transpose(), 1;
  }
  return m;
}

// A grid of nx × ny quads on [0, width] × [0, height], z = 0, counter-clockwise seen from +z.
TriangleMesh grid(int nx, int ny, double width, double height) {
  TriangleMesh mesh;
  mesh.V.resize((nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      mesh.V.row(j * (nx + 1) + i) << static_cast<float>(width * i / nx), static_cast<float>(height * j / ny), 0.f;
    }
  }
  mesh.F.resize(2 * nx * ny, 3);
  int f = 0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
      mesh.F.row(f++) << a, b, d;
      mesh.F.row(f++) << a, d, c;
    }
  }
  return mesh;
}

double signed_area(const CornerUvs& uv, Eigen::Index f) {
  const Eigen::Vector2d a = uv.row(3 * f), b = uv.row(3 * f + 1), c = uv.row(3 * f + 2);
  return 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}

double orient(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

bool strictly_inside(const Eigen::Vector2d& p, const Eigen::Vector2d t[3]) {
  return orient(t[0], t[1], p) > 1e-15 && orient(t[1], t[2], p) > 1e-15 && orient(t[2], t[0], p) > 1e-15;
}

// Whether the interiors of two counter-clockwise triangles intersect: two edges cross properly,
// a vertex or the centroid of one lies strictly inside the other.
bool interiors_overlap(const Eigen::Vector2d s[3], const Eigen::Vector2d t[3]) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector2d &p = s[i], &q = s[(i + 1) % 3], &r = t[j], &u = t[(j + 1) % 3];
      const double o1 = orient(p, q, r), o2 = orient(p, q, u), o3 = orient(r, u, p), o4 = orient(r, u, q);
      if (((o1 > 1e-15 && o2 < -1e-15) || (o1 < -1e-15 && o2 > 1e-15)) &&
          ((o3 > 1e-15 && o4 < -1e-15) || (o3 < -1e-15 && o4 > 1e-15))) {
        return true;
      }
    }
  }
  const Eigen::Vector2d cs = (s[0] + s[1] + s[2]) / 3, ct = (t[0] + t[1] + t[2]) / 3;
  if (strictly_inside(cs, t) || strictly_inside(ct, s)) return true;
  for (int i = 0; i < 3; ++i) {
    if (strictly_inside(s[i], t) || strictly_inside(t[i], s)) return true;
  }
  return false;
}

// Every invariant of a valid atlas, by brute force.
void expect_valid_atlas(const FaceMatrix& faces, const Atlas& atlas) {
  const Eigen::Index F = faces.rows();
  ASSERT_EQ(atlas.uvs.rows(), 3 * F);
  ASSERT_EQ(atlas.chart_of_face.size(), static_cast<size_t>(F));
  EXPECT_GE(atlas.uvs.minCoeff(), 0.0);
  EXPECT_LE(atlas.uvs.maxCoeff(), 1.0);
  for (Eigen::Index f = 0; f < F; ++f) EXPECT_GT(signed_area(atlas.uvs, f), 0.0) << "face " << f << " flipped";
  // No two triangles overlap, within or between charts.
  long overlaps = 0;
  for (Eigen::Index f = 0; f < F; ++f) {
    const Eigen::Vector2d s[3] = {atlas.uvs.row(3 * f), atlas.uvs.row(3 * f + 1), atlas.uvs.row(3 * f + 2)};
    for (Eigen::Index g = f + 1; g < F; ++g) {
      const Eigen::Vector2d t[3] = {atlas.uvs.row(3 * g), atlas.uvs.row(3 * g + 1), atlas.uvs.row(3 * g + 2)};
      overlaps += interiors_overlap(s, t) ? 1 : 0;
    }
  }
  EXPECT_EQ(overlaps, 0);
  // Inside a chart, a vertex has one UV (seams only between charts).
  std::unordered_map<long, Eigen::Vector2d> uv_of;
  for (Eigen::Index f = 0; f < F; ++f) {
    for (int k = 0; k < 3; ++k) {
      const long key = static_cast<long>(atlas.chart_of_face[static_cast<size_t>(f)]) * 1000000 + faces(f, k);
      const Eigen::Vector2d uv = atlas.uvs.row(3 * f + k);
      const auto [it, fresh] = uv_of.emplace(key, uv);
      if (!fresh) {
        EXPECT_EQ(it->second, uv) << "vertex " << faces(f, k) << " has two UVs in one chart";
      }
    }
  }
  // Every chart connected and a disc: V − E + F = 1 and its border edges form one loop.
  for (int c = 0; c < atlas.chart_count; ++c) {
    std::vector<Eigen::Index> members;
    for (Eigen::Index f = 0; f < F; ++f) {
      if (atlas.chart_of_face[static_cast<size_t>(f)] == c) members.push_back(f);
    }
    ASSERT_FALSE(members.empty()) << "chart " << c;
    std::set<int> vertices;
    std::set<std::pair<int, int>> edges, directed;
    for (Eigen::Index f : members) {
      for (int k = 0; k < 3; ++k) {
        const int a = faces(f, k), b = faces(f, (k + 1) % 3);
        vertices.insert(a);
        edges.insert({std::min(a, b), std::max(a, b)});
        directed.insert({a, b});
      }
    }
    const long euler = static_cast<long>(vertices.size()) - static_cast<long>(edges.size()) + static_cast<long>(members.size());
    EXPECT_EQ(euler, 1) << "chart " << c;
    std::map<int, int> next;
    for (const auto& [a, b] : directed) {
      if (!directed.count({b, a})) {
        EXPECT_TRUE(next.emplace(a, b).second) << "chart " << c << " pinches at " << a;
      }
    }
    ASSERT_FALSE(next.empty()) << "chart " << c << " is closed";
    int v = next.begin()->first;
    size_t steps = 0;
    do {
      v = next[v];
      ++steps;
    } while (v != next.begin()->first && steps <= next.size());
    EXPECT_EQ(steps, next.size()) << "chart " << c << " has more than one border loop";
    // Connected across edges.
    std::set<Eigen::Index> seen{members.front()};
    std::vector<Eigen::Index> stack{members.front()};
    while (!stack.empty()) {
      const Eigen::Index f = stack.back();
      stack.pop_back();
      for (Eigen::Index g : members) {
        if (seen.count(g)) continue;
        int shared = 0;
        for (int i = 0; i < 3; ++i) {
          for (int j = 0; j < 3; ++j) shared += faces(f, i) == faces(g, j) ? 1 : 0;
        }
        if (shared == 2) {
          seen.insert(g);
          stack.push_back(g);
        }
      }
    }
    EXPECT_EQ(seen.size(), members.size()) << "chart " << c << " is not connected";
  }
}

TEST(Stretch, OfAnAffineMapIsTheSingularValuesOfItsInverse) {
  // A flat grid with UV = A (x, y): the map UV → surface is A⁻¹, whose singular values Γ ≥ γ give
  // L2 = √((Γ² + γ²)/2) and L∞ = Γ; Sander's normalisation multiplies by √(UV area / area) = √|det A|.
  const TriangleMesh mesh = grid(5, 4, 2.0, 1.5);
  Eigen::Matrix2d A;
  A << 1.5, 0.4, -0.3, 0.8;
  CornerUvs uv(3 * mesh.F.rows(), 2);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      uv.row(3 * f + k) = (A * mesh.V.row(mesh.F(f, k)).head<2>().cast<double>().transpose()).transpose();
    }
  }
  const Eigen::JacobiSVD<Eigen::Matrix2d> svd(A.inverse());
  const double G = svd.singularValues()(0), g = svd.singularValues()(1);
  const double normalisation = std::sqrt(std::abs(A.determinant()));
  const Stretch s = stretch(face_metrics(mesh.V, mesh.F), uv);
  EXPECT_NEAR(s.l2, std::sqrt((G * G + g * g) / 2) * normalisation, 1e-6);
  EXPECT_NEAR(s.linf, G * normalisation, 1e-6);
  EXPECT_EQ(s.flipped, 0);
  // A mirror image flips every triangle.
  CornerUvs mirrored = uv;
  mirrored.col(0) *= -1;
  EXPECT_EQ(stretch(face_metrics(mesh.V, mesh.F), mirrored).flipped, mesh.F.rows());
  // The metric of a pose distribution: a model posed by one pose has the Gram matrices of that pose.
  const auto model = rigid_model(mesh.V, mesh.F);
  auto metrics = rest_pose_metrics(model.skeleton);
  ASSERT_TRUE(metrics.ok());
  auto g_model = face_metrics(model, *metrics);
  ASSERT_TRUE(g_model.ok());
  EXPECT_LT((*g_model - face_metrics(mesh.V, mesh.F)).cwiseAbs().maxCoeff(), 1e-6);
}

// Part of a cylinder of radius r (angle < 2π, so a disc) and a plane bent by 90° along a line:
// both developable, so the flattening must reach L2 = 1 (tolerance 2e-3: the line search stops
// at a relative improvement of 1e-4 per sweep).
TEST(Flatten, DevelopablePatchesFlattenWithoutStretch) {
  const TriangleMesh plane = grid(16, 8, 1.0, 1.0);
  TriangleMesh cylinder = plane, bent = plane;
  const double radius = 0.3;
  for (Eigen::Index v = 0; v < plane.V.rows(); ++v) {
    const double x = plane.V(v, 0), y = plane.V(v, 1);
    const double angle = 1.8 * M_PI * x;  // unrolled length 1.8π r
    cylinder.V.row(v) << static_cast<float>(radius * std::sin(angle)), static_cast<float>(y),
        static_cast<float>(radius * (1 - std::cos(angle)));
    // Bent along x = 0.5: the far half turned up into z.
    if (x > 0.5) bent.V.row(v) << 0.5f, static_cast<float>(y), static_cast<float>(x - 0.5);
  }
  for (const TriangleMesh* mesh : {&cylinder, &bent}) {
    FlattenOptions options;
    options.max_sweeps = 500;
    auto map = flatten_chart(mesh->F, static_cast<int>(mesh->V.rows()), face_metrics(mesh->V, mesh->F), options);
    ASSERT_TRUE(map.ok()) << map.error().message;
    EXPECT_NEAR(map->l2, 1.0, 2e-3);
    CornerUvs corners(3 * mesh->F.rows(), 2);
    for (Eigen::Index f = 0; f < mesh->F.rows(); ++f) {
      for (int k = 0; k < 3; ++k) corners.row(3 * f + k) = map->uv.row(mesh->F(f, k));
    }
    const Stretch s = stretch(face_metrics(mesh->V, mesh->F), corners);
    EXPECT_EQ(s.flipped, 0);
    EXPECT_NEAR(s.l2, map->l2, 1e-9);
  }
}

TEST(Flatten, RefusesAChartThatIsNotADisc) {
  const testing::ArticulatedTube tube = testing::make_tube(1, 6, 1, 1);  // an open tube: an annulus
  auto map = flatten_chart(tube.faces, static_cast<int>(tube.rest.rows()), face_metrics(tube.rest, tube.faces), {});
  ASSERT_FALSE(map.ok());
  EXPECT_EQ(map.error().code, ErrorCode::kInvalidArgument);
}

TEST(Atlas, OfATubeIsOneToOneWithDiscCharts) {
  // A tube is not a disc: however few charts are asked for, the atlas must cut it into discs.
  const testing::ArticulatedTube tube = testing::make_tube(3, 4, 1, 3);
  const auto model = rigid_model(tube.rest, tube.faces);
  auto metrics = rest_pose_metrics(model.skeleton);
  ASSERT_TRUE(metrics.ok());
  for (int charts : {1, 3}) {
    AtlasOptions options;
    options.chart_count = charts;
    auto built = build_atlas(model, *metrics, options);
    ASSERT_TRUE(built.ok()) << built.error().message;
    EXPECT_GE(built->atlas.chart_count, 2);
    expect_valid_atlas(tube.faces, built->atlas);
    EXPECT_GT(built->utilisation, 0.0);
    EXPECT_LE(built->utilisation, 1.0);
    // The reported stretch is the stretch of the stored UVs.
    EXPECT_NEAR(built->l2, stretch(face_metrics(tube.rest, tube.faces), built->atlas.uvs).l2, 1e-9);
  }
}

// Issue #55 item 15: the atlas reports its stages for a command line's bar — segmentation, then
// every chart flattened (one report per chart, the count reaching the chart count), then packing —
// each count within its total.
TEST(Atlas, ReportsItsStagesAsItGoes) {
  const testing::ArticulatedTube tube = testing::make_tube(3, 4, 1, 3);
  const auto model = rigid_model(tube.rest, tube.faces);
  auto metrics = rest_pose_metrics(model.skeleton);
  ASSERT_TRUE(metrics.ok());
  std::vector<std::string> stages;
  int64_t flattened = 0;
  AtlasOptions options;
  options.chart_count = 3;
  options.progress = [&](std::string_view stage, int64_t done, int64_t total) {
    EXPECT_LE(done, total) << stage;
    if (stages.empty() || stages.back() != stage) stages.emplace_back(stage);
    if (stage == "flatten charts") flattened = std::max(flattened, done);
  };
  auto built = build_atlas(model, *metrics, options);
  ASSERT_TRUE(built.ok()) << built.error().message;
  ASSERT_GE(stages.size(), 3u);
  EXPECT_EQ(stages.front(), "segment charts");
  EXPECT_EQ(stages[1], "flatten charts");
  EXPECT_EQ(stages.back(), "pack charts");
  EXPECT_GE(flattened, 1);
  // Round 0 flattens every segmented chart; split rounds only add charts.
  EXPECT_EQ(built->split_rounds == 0, flattened == built->atlas.chart_count);
  EXPECT_LE(flattened, built->atlas.chart_count);
}

// A strip [0, 2] × [0, 1] skinned to two bones: bone 1 slides along x by up to 1.5 in the poses,
// bone 0 stays; across the blend band x ∈ [0.6, 1.4] the surface stretches up to ×(1 + 1.5/0.8)
// along x, elsewhere it moves rigidly. The rest pose does not show it.
struct SlidingStrip {
  as::AnimationSpaceModel model;
  std::vector<as::TransformList> training, held_out;
};

SlidingStrip sliding_strip() {
  const TriangleMesh mesh = grid(24, 8, 2.0, 1.0);
  SlidingStrip s;
  as::AnimationSpaceModel& m = s.model;
  m.skeleton.parents = {-1, 0};
  m.skeleton.rest = {Eigen::Matrix4d::Identity(), Eigen::Matrix4d::Identity()};
  m.faces = mesh.F;
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v) {
    const Eigen::Vector4d point(mesh.V(v, 0), mesh.V(v, 1), mesh.V(v, 2), 1);
    const double w1 = std::clamp((mesh.V(v, 0) - 0.6) / 0.8, 0.0, 1.0);
    // p_j = w_j Ĝ_j⁻¹ v̂ (both rest transforms are the identity).
    for (int j = 0; j < 2; ++j) {
      const double w = j == 0 ? 1 - w1 : w1;
      if (w == 0) continue;
      m.influences.bones.push_back(j);
      m.positions.conservativeResize(4, m.positions.cols() + 1);
      m.positions.col(m.positions.cols() - 1) = w * point;
    }
    m.influences.offsets.push_back(static_cast<int32_t>(m.influences.bones.size()));
  }
  const auto pose = [](double t) {
    as::TransformList G{Eigen::Matrix4d::Identity(), Eigen::Matrix4d::Identity()};
    G[1](0, 3) = t;
    return G;
  };
  for (int k = 0; k <= 10; ++k) s.training.push_back(pose(1.5 * k / 10));
  for (int k = 0; k < 10; ++k) s.held_out.push_back(pose(1.5 * (k + 0.5) / 10));  // between the training poses
  return s;
}

TEST(Atlas, PoseAwareFlatteningBeatsTheRestPoseOnesAcrossPoses) {
  const SlidingStrip s = sliding_strip();
  ASSERT_TRUE(as::validate(s.model).ok());
  auto poses = as::metrics_from_poses(s.model.skeleton, s.training);
  auto rest = rest_pose_metrics(s.model.skeleton);
  ASSERT_TRUE(poses.ok() && rest.ok());
  // The same charts for both, so only the flattening differs.
  AtlasOptions options;
  options.chart_count = 1;
  auto ours = build_atlas(s.model, *poses, options);
  ASSERT_TRUE(ours.ok()) << ours.error().message;
  auto rest_g = face_metrics(s.model, *rest);
  ASSERT_TRUE(rest_g.ok());
  auto anchor = flatten_and_pack(s.model.faces, *rest_g, ours->atlas.chart_of_face, options);
  ASSERT_TRUE(anchor.ok()) << anchor.error().message;
  expect_valid_atlas(s.model.faces, ours->atlas);
  expect_valid_atlas(s.model.faces, anchor->atlas);

  // Brute force: pose the mesh in held-out poses and measure each pose's stretch.
  std::vector<PointMatrix> posed(s.held_out.size());
  for (size_t k = 0; k < s.held_out.size(); ++k) as::evaluate(s.model, s.held_out[k], posed[k]);
  const Stretch ours_poses = stretch_across_poses(posed, s.model.faces, ours->atlas.uvs);
  const Stretch anchor_poses = stretch_across_poses(posed, s.model.faces, anchor->atlas.uvs);
  EXPECT_LT(ours_poses.l2, anchor_poses.l2 - 0.02) << ours_poses.l2 << " vs " << anchor_poses.l2;
  // And the rest-pose flattening is the better one in the rest pose, which it was made for.
  PointMatrix rest_points;
  as::evaluate(s.model, s.model.skeleton.rest, rest_points);
  EXPECT_LT(stretch_across_poses({rest_points}, s.model.faces, anchor->atlas.uvs).l2,
            stretch_across_poses({rest_points}, s.model.faces, ours->atlas.uvs).l2);
}

TEST(Atlas, IsValidAndAsGoodAtAnyScale) {
  // The same (irregular) tube in units about 10⁴ times smaller and larger — powers of two, so the
  // points are exact: the same charts, one-to-one with discs, and the same stretch.
  testing::ArticulatedTube tube = testing::make_tube(3, 4, 1, 3);
  std::mt19937_64 engine(5);
  std::uniform_real_distribution<float> jitter(0.8f, 1.2f);
  for (Eigen::Index v = 0; v < tube.rest.rows(); ++v) tube.rest.block<1, 2>(v, 1) *= jitter(engine);
  std::vector<AtlasReport> reports;
  for (const float scale : {1.0f, std::ldexp(1.0f, -13), std::ldexp(1.0f, 13)}) {
    SCOPED_TRACE("scale " + std::to_string(scale));
    const PointMatrix points = tube.rest * scale;
    const auto model = rigid_model(points, tube.faces);
    auto metrics = rest_pose_metrics(model.skeleton);
    ASSERT_TRUE(metrics.ok());
    AtlasOptions options;
    options.chart_count = 3;
    auto built = build_atlas(model, *metrics, options);
    ASSERT_TRUE(built.ok()) << built.error().message;
    expect_valid_atlas(tube.faces, built->atlas);
    reports.push_back(std::move(*built));
  }
  for (size_t i = 1; i < reports.size(); ++i) {
    EXPECT_EQ(reports[i].atlas.chart_count, reports[0].atlas.chart_count);
    EXPECT_EQ(reports[i].atlas.chart_of_face, reports[0].atlas.chart_of_face);
    EXPECT_NEAR(reports[i].l2, reports[0].l2, 1e-3);
  }
}

TEST(Atlas, RefusesBadInput) {
  const TriangleMesh plane = grid(2, 2, 1, 1);
  auto model = rigid_model(plane.V, plane.F);
  auto metrics = rest_pose_metrics(model.skeleton);
  ASSERT_TRUE(metrics.ok());
  AtlasOptions options;
  options.chart_count = -1;
  EXPECT_EQ(build_atlas(model, *metrics, options).error().code, ErrorCode::kInvalidArgument);
  model.faces.resize(0, 3);
  EXPECT_EQ(build_atlas(model, *metrics, {}).error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace animspace::atlas
