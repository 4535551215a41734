#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "core/animspace/import.h"
#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

using testing::random_pose;

constexpr double kDegree = std::numbers::pi / 180.0;

// A chain root → 1 → 2 → 3 with joints at x = 0, 1, 2 (rest rotations identity), scaled.
Skeleton chain_skeleton(double scale = 1.0) {
  Skeleton skeleton = root_only_skeleton();
  for (int j = 1; j <= 3; ++j) {
    skeleton.parents.push_back(j - 1);
    skeleton.rest.push_back(make_transform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(scale * (j - 1), 0, 0)));
  }
  return skeleton;
}

// An open tube along x from 0 to 3·scale, radius 0.3·scale, faces counter-clockwise seen from
// outside; weights are normalised hat functions of x centred on bones 1, 2, 3 (smooth
// blending across the joints), or all on one bone when `rigid_bone` > 0.
LinearBlendModel skinned_tube(double scale = 1.0, int rigid_bone = 0, int rings = 25, int segments = 16) {
  LinearBlendModel model;
  model.skeleton = chain_skeleton(scale);
  model.rest_points.resize(3, rings * segments);
  std::vector<double> weights;
  for (int r = 0; r < rings; ++r) {
    const double x = 3.0 * r / (rings - 1);
    for (int c = 0; c < segments; ++c) {
      const double theta = 2 * std::numbers::pi * c / segments;
      model.rest_points.col(r * segments + c) = scale * Eigen::Vector3d(x, 0.3 * std::cos(theta), 0.3 * std::sin(theta));
      if (rigid_bone > 0) {
        model.influences.bones.push_back(rigid_bone);
        weights.push_back(1.0);
      } else {
        double w[3], sum = 0;
        for (int b = 0; b < 3; ++b) sum += (w[b] = std::max(0.0, 1.0 - std::abs(x - (b + 0.5)) / 1.2));
        for (int b = 0; b < 3; ++b) {
          if (w[b] == 0) continue;
          model.influences.bones.push_back(b + 1);
          weights.push_back(w[b] / sum);
        }
      }
      model.influences.offsets.push_back(static_cast<int32_t>(model.influences.bones.size()));
    }
  }
  model.weights = Eigen::Map<Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  model.faces.resize(2 * (rings - 1) * segments, 3);
  int f = 0;
  for (int r = 0; r + 1 < rings; ++r) {
    for (int c = 0; c < segments; ++c) {
      const int a = r * segments + c, b = r * segments + (c + 1) % segments;
      model.faces.row(f++) << a, b, b + segments;
      model.faces.row(f++) << a, b + segments, a + segments;
    }
  }
  return model;
}

// SSD in double, written out: v = Σ_j w_j G_j Ĝ_j⁻¹ v̂.
Eigen::MatrixX3d ssd_positions(const LinearBlendModel& model, const TransformList& globals) {
  Eigen::MatrixX3d out(model.vertex_count(), 3);
  for (int i = 0; i < model.vertex_count(); ++i) {
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      const size_t j = static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)]);
      v += model.weights(k) * globals[j] * model.skeleton.rest[j].inverse() * model.rest_points.col(i).homogeneous();
    }
    out.row(i) = v.head<3>().transpose();
  }
  return out;
}

// Area-weighted vertex normals, computed here independently of tangents.cpp.
Eigen::MatrixX3d reference_normals(const Eigen::MatrixX3d& V, const FaceMatrix& F) {
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(V.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::RowVector3d e1 = V.row(F(f, 1)) - V.row(F(f, 0)), e2 = V.row(F(f, 2)) - V.row(F(f, 0));
    const Eigen::RowVector3d n = e1.cross(e2);
    for (int c = 0; c < 3; ++c) N.row(F(f, c)) += n;
  }
  N.rowwise().normalize();
  return N;
}

double angle_between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

AnimationSpaceModel with_tangents(AnimationSpaceModel model, const TangentPlanes& planes) {
  model.tangent_s = planes.s;
  model.tangent_t = planes.t;
  return model;
}

// §4.3.2: the eq. 4.8 tangent plane reproduces SSD's normal transform n ∝ M⁻ᵀ n̂ (eq. 3.35,
// M the blended linear part), oriented by det M, in every pose.
TEST(TangentNormalsTest, SsdTangentPlanesReproduceInverseTransposeNormals) {
  const LinearBlendModel ssd = skinned_tube();
  const AnimationSpaceModel model = from_linear_blend(ssd);
  // Arbitrary rest normals (not the geometry's): the construction must not depend on them.
  std::mt19937_64 engine(7);
  std::normal_distribution<double> normal;
  Eigen::MatrixX3d rest_normals(model.vertex_count(), 3);
  for (int i = 0; i < model.vertex_count(); ++i) rest_normals.row(i) << normal(engine), normal(engine), normal(engine);
  auto planes = tangent_planes_from_normals(model, rest_normals);
  ASSERT_TRUE(planes.ok()) << planes.error().message;
  EXPECT_EQ(planes->degenerate_vertices, 0);
  const AnimationSpaceModel shaded = with_tangents(model, *planes);
  ASSERT_TRUE(validate(shaded, 1e-12).ok()) << validate(shaded).error().message;

  // Rest-pose projection: Ĝ s and Ĝ t are orthonormal, perpendicular to n̂, with ŝ × t̂ = n̂.
  for (int i = 0; i < model.vertex_count(); ++i) {
    Eigen::Vector4d s = Eigen::Vector4d::Zero(), t = Eigen::Vector4d::Zero();
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      const auto& rest = model.skeleton.rest[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])];
      s += rest * planes->s.col(k);
      t += rest * planes->t.col(k);
    }
    EXPECT_NEAR(s.norm(), 1.0, 1e-12);
    EXPECT_NEAR(t.norm(), 1.0, 1e-12);
    EXPECT_NEAR(s.dot(t), 0.0, 1e-12);
    EXPECT_TRUE(s.head<3>().cross(t.head<3>()).isApprox(rest_normals.row(i).transpose().normalized(), 1e-12));
  }

  for (int pose = 0; pose < 6; ++pose) {
    const TransformList globals = random_pose(ssd.skeleton, engine, 2.5);
    PointMatrix normals;
    evaluate_normals(shaded, globals, normals);
    for (int i = 0; i < model.vertex_count(); ++i) {
      Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
      for (int k = ssd.influences.begin(i); k < ssd.influences.end(i); ++k) {
        const size_t j = static_cast<size_t>(ssd.influences.bones[static_cast<size_t>(k)]);
        M += ssd.weights(k) * (globals[j] * ssd.skeleton.rest[j].inverse()).topLeftCorner<3, 3>();
      }
      const double sign = M.determinant() > 0 ? 1.0 : -1.0;
      const Eigen::Vector3d expected = sign * (M.inverse().transpose() * rest_normals.row(i).transpose()).normalized();
      EXPECT_LT(angle_between(normals.row(i).cast<double>().transpose(), expected), 1e-5) << "pose " << pose << " vertex " << i;
    }
  }
}

TEST(TangentNormalsTest, ZeroNormalIsDegenerateAndBadInputIsNamed) {
  const AnimationSpaceModel model = from_linear_blend(skinned_tube());
  Eigen::MatrixX3d rest_normals = geometry::area_weighted_normals(rest_positions(model), model.faces);
  rest_normals.row(12).setZero();
  auto planes = tangent_planes_from_normals(model, rest_normals);
  ASSERT_TRUE(planes.ok());
  EXPECT_EQ(planes->degenerate_vertices, 1);
  PointMatrix normals;
  evaluate_normals(with_tangents(model, *planes), model.skeleton.rest, normals);
  EXPECT_EQ(normals.row(12).norm(), 0.0f);
  EXPECT_NEAR(normals.row(13).norm(), 1.0f, 1e-6f);

  rest_normals(30, 1) = std::nan("");
  auto nan = tangent_planes_from_normals(model, rest_normals);
  ASSERT_FALSE(nan.ok());
  EXPECT_EQ(nan.error().message, "rest normal of vertex 30 is not finite");
  auto short_normals = tangent_planes_from_normals(model, rest_normals.topRows(5));
  ASSERT_FALSE(short_normals.ok());
  EXPECT_NE(short_normals.error().message.find("expected 400 rows"), std::string::npos) << short_normals.error().message;
}

// A rigid piece (one bone): fitted planes are the rest faces' planes carried along, so the
// normals are exactly the area-weighted normals of the posed mesh.
TEST(TangentFitTest, RigidModelGivesAreaWeightedNormalsInEveryPose) {
  const LinearBlendModel ssd = skinned_tube(1.0, 2);
  const AnimationSpaceModel model = from_linear_blend(ssd);
  auto planes = fit_tangent_planes(model);
  ASSERT_TRUE(planes.ok()) << planes.error().message;
  EXPECT_EQ(planes->degenerate_vertices, 0);
  const AnimationSpaceModel shaded = with_tangents(model, *planes);
  ASSERT_TRUE(validate(shaded, 1e-12).ok());
  std::mt19937_64 engine(11);
  for (int pose = 0; pose < 4; ++pose) {
    const TransformList globals = random_pose(ssd.skeleton, engine, 3.0);
    const Eigen::MatrixX3d expected = reference_normals(ssd_positions(ssd, globals), ssd.faces);
    PointMatrix normals;
    evaluate_normals(shaded, globals, normals);
    for (int i = 0; i < model.vertex_count(); ++i) {
      EXPECT_LT(angle_between(normals.row(i).cast<double>().transpose(), expected.row(i).transpose()), 1e-5) << i;
    }
  }
}

// A flat sheet blended with the same weights everywhere deforms affinely, so it stays flat: the
// fitted normal must be exactly perpendicular to it, on the side of its faces' normals.
TEST(TangentFitTest, FlatBlendedSheetNormalsArePerpendicularInEveryPose) {
  LinearBlendModel ssd;
  ssd.skeleton = chain_skeleton();
  const int n = 9;
  ssd.rest_points.resize(3, n * n);
  std::vector<double> weights;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      ssd.rest_points.col(r * n + c) = Eigen::Vector3d(0.2 + 2.0 * c / (n - 1), -0.5 + 1.0 * r / (n - 1), 0.1 * c);
      ssd.influences.bones.insert(ssd.influences.bones.end(), {1, 2, 3});
      weights.insert(weights.end(), {0.2, 0.5, 0.3});
      ssd.influences.offsets.push_back(static_cast<int32_t>(ssd.influences.bones.size()));
    }
  }
  ssd.weights = Eigen::Map<Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  ssd.faces.resize(2 * (n - 1) * (n - 1), 3);
  int f = 0;
  for (int r = 0; r + 1 < n; ++r) {
    for (int c = 0; c + 1 < n; ++c) {
      const int a = r * n + c;
      ssd.faces.row(f++) << a, a + 1, a + n + 1;
      ssd.faces.row(f++) << a, a + n + 1, a + n;
    }
  }
  const AnimationSpaceModel model = from_linear_blend(ssd);
  auto planes = fit_tangent_planes(model);
  ASSERT_TRUE(planes.ok()) << planes.error().message;
  const AnimationSpaceModel shaded = with_tangents(model, *planes);
  std::mt19937_64 engine(12);
  for (int pose = 0; pose < 4; ++pose) {
    const TransformList globals = random_pose(ssd.skeleton, engine, 1.5);
    const Eigen::MatrixX3d V = ssd_positions(ssd, globals);
    const Eigen::Vector3d face_normal = (V.row(1) - V.row(0)).cross(V.row(n + 1) - V.row(0)).normalized().transpose();
    PointMatrix normals;
    evaluate_normals(shaded, globals, normals);
    for (int i = 0; i < model.vertex_count(); ++i) {
      const Eigen::Vector3d normal = normals.row(i).cast<double>().transpose();
      EXPECT_LT(angle_between(normal, face_normal), 1e-5) << "pose " << pose << " vertex " << i;
      // Perpendicular to the posed sheet's edges (the sheet stays flat).
      const Eigen::Vector3d across = (V.row(n * n - 1) - V.row(0)).transpose();
      EXPECT_LT(std::abs(normal.dot(across.normalized())), 1e-6);
    }
  }
}

struct FitStatistics {
  double median_degrees = 0;
  double p99_degrees = 0;
  double max_degrees = 0;
  double max_inside_degrees = 0;  // over vertices whose neighbours all have the vertex's bones
};

FitStatistics fit_statistics(const LinearBlendModel& ssd, uint64_t seed, double max_angle) {
  const AnimationSpaceModel model = from_linear_blend(ssd);
  auto planes = fit_tangent_planes(model);
  EXPECT_TRUE(planes.ok());
  EXPECT_EQ(planes->degenerate_vertices, 0);
  const AnimationSpaceModel shaded = with_tangents(model, *planes);
  // Vertices on the edge of an influence set: a neighbour has a bone they lack.
  std::vector<bool> on_edge(static_cast<size_t>(model.vertex_count()), false);
  const auto bones_of = [&](int v) {
    return std::vector<int32_t>(model.influences.bones.begin() + model.influences.begin(v),
                                model.influences.bones.begin() + model.influences.end(v));
  };
  for (Eigen::Index f = 0; f < model.faces.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const std::vector<int32_t> mine = bones_of(model.faces(f, c));
      for (int d = 0; d < 3; ++d) {
        for (const int32_t bone : bones_of(model.faces(f, d))) {
          if (std::find(mine.begin(), mine.end(), bone) == mine.end()) on_edge[static_cast<size_t>(model.faces(f, c))] = true;
        }
      }
    }
  }
  std::mt19937_64 engine(seed);
  std::vector<double> angles;
  FitStatistics statistics;
  for (int pose = 0; pose < 8; ++pose) {
    const TransformList globals = random_pose(ssd.skeleton, engine, max_angle);
    const Eigen::MatrixX3d expected = reference_normals(ssd_positions(ssd, globals), ssd.faces);
    PointMatrix normals;
    evaluate_normals(shaded, globals, normals);
    for (int i = 0; i < model.vertex_count(); ++i) {
      angles.push_back(angle_between(normals.row(i).cast<double>().transpose(), expected.row(i).transpose()) / kDegree);
      if (!on_edge[static_cast<size_t>(i)]) statistics.max_inside_degrees = std::max(statistics.max_inside_degrees, angles.back());
    }
  }
  std::sort(angles.begin(), angles.end());
  statistics.median_degrees = angles[angles.size() / 2];
  statistics.p99_degrees = angles[angles.size() * 99 / 100];
  statistics.max_degrees = angles.back();
  return statistics;
}

// §4.3.1: on a smoothly blended SSD tube, the fitted planes give normals close to the
// area-weighted normals of the posed mesh in random poses (every joint turned up to 45° about a
// random axis, twists included). The largest errors sit on the rings where a bone's weight
// starts (a kink in the weights): the tangent plane may only use the vertex's own bones.
TEST(TangentFitTest, BlendedTubeNormalsFollowPosedGeometry) {
  const FitStatistics statistics = fit_statistics(skinned_tube(), 13, 45 * kDegree);
  std::printf("fitted vs area-weighted posed normals: median %.3f°, 99%% %.3f°, max %.3f°; %.3f° away from "
              "influence-set edges\n",
              statistics.median_degrees, statistics.p99_degrees, statistics.max_degrees, statistics.max_inside_degrees);
  EXPECT_LT(statistics.median_degrees, 1.0);
  EXPECT_LT(statistics.p99_degrees, 5.0);
  EXPECT_LT(statistics.max_degrees, 8.0);
  EXPECT_LT(statistics.max_inside_degrees, 2.0);
}

// Scale robustness (STYLE §6): the default fitting metric scales with the model, so the normals
// of a model scaled by 1e-4 or 1e4 are those of the unscaled one.
TEST(TangentFitTest, NormalsDoNotDependOnModelScale) {
  std::mt19937_64 engine(14);
  const LinearBlendModel unit = skinned_tube(1.0);
  const TransformList unit_pose = random_pose(unit.skeleton, engine, 1.0);
  auto unit_planes = fit_tangent_planes(from_linear_blend(unit));
  ASSERT_TRUE(unit_planes.ok());
  PointMatrix unit_normals;
  evaluate_normals(with_tangents(from_linear_blend(unit), *unit_planes), unit_pose, unit_normals);
  for (const double scale : {1e-4, 1e4}) {
    const LinearBlendModel scaled = skinned_tube(scale);
    TransformList pose = unit_pose;
    for (Transform& G : pose) G.topRightCorner<3, 1>() *= scale;
    const AnimationSpaceModel model = from_linear_blend(scaled);
    auto planes = fit_tangent_planes(model);
    ASSERT_TRUE(planes.ok());
    PointMatrix normals;
    evaluate_normals(with_tangents(model, *planes), pose, normals);
    EXPECT_LT((normals - unit_normals).cwiseAbs().maxCoeff(), 1e-5f) << "scale " << scale;
  }
}

TEST(TangentFitTest, RejectsPointSets) {
  AnimationSpaceModel model = from_linear_blend(skinned_tube());
  model.faces.resize(0, 3);
  auto planes = fit_tangent_planes(model);
  ASSERT_FALSE(planes.ok());
  EXPECT_EQ(planes.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(planes.error().message.find("no faces"), std::string::npos);
}

}  // namespace
}  // namespace animspace::animation_space
