// The surface filter (issue #38 item 1) against hand-worked cases: a constant irradiance stays
// constant for any k and any albedo, a linear irradiance on a plane is kept where the
// neighbourhood is symmetric, the two sides of a fold and two albedos do not mix, and a noisy
// constant field's variance falls as 1/k by the Gaussian's effective neighbour count.
#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/illumination/surface_filter.h"

namespace animspace::illumination {
namespace {

// An n × n grid of spacing h in the plane through `origin` spanned by unit u and v (normal u × v),
// albedo 0.5 everywhere.
SurfaceMesh grid(int n, double h, const Eigen::Vector3d& origin = Eigen::Vector3d::Zero(),
                 const Eigen::Vector3d& u = Eigen::Vector3d::UnitX(), const Eigen::Vector3d& v = Eigen::Vector3d::UnitY()) {
  SurfaceMesh s;
  s.vertices.resize(n * n, 3);
  s.normals.resize(n * n, 3);
  s.albedo = PointMatrix::Constant(n * n, 3, 0.5f);
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      s.vertices.row(y * n + x) = (origin + h * x * u + h * y * v).transpose().cast<float>();
      s.normals.row(y * n + x) = u.cross(v).transpose().cast<float>();
    }
  }
  s.faces.resize(2 * (n - 1) * (n - 1), 3);
  int t = 0;
  for (int y = 0; y + 1 < n; ++y) {
    for (int x = 0; x + 1 < n; ++x) {
      const int a = y * n + x;
      s.faces.row(t++) << a, a + 1, a + n + 1;
      s.faces.row(t++) << a, a + n + 1, a + n;
    }
  }
  return s;
}

// Radiance L = ρ ⊙ E for an irradiance field E(point) (point-major RGB).
template <typename Irradiance>
Eigen::VectorXf radiance(const SurfaceMesh& s, Irradiance E) {
  Eigen::VectorXf L(3 * s.vertices.rows());
  for (long i = 0; i < s.vertices.rows(); ++i) {
    const Eigen::Vector3d e = E(i);
    for (int c = 0; c < 3; ++c) L[3 * i + c] = static_cast<float>(s.albedo(i, c) * e[c]);
  }
  return L;
}

SurfaceFilter precompute(const SurfaceMesh& s, int k, bool linear = false) {
  auto filter = surface_filter_precompute(s, {k, 0.9, linear});
  EXPECT_TRUE(filter.ok()) << filter.error().message;
  return filter.ok() ? std::move(*filter) : SurfaceFilter{};
}

TEST(SurfaceFilterTest, RadiusHoldsKPointsAtTheMeanDensity) {
  // 41 × 41 points over (40 h)² of area: πr² · N / A = k.
  const SurfaceMesh s = grid(41, 0.01);
  const SurfaceFilter f = precompute(s, 30);
  EXPECT_NEAR(f.radius, std::sqrt(30 * 0.16 / (M_PI * 41 * 41)), 1e-9);
  // An interior point's neighbour count is about k (a lattice disc).
  const long centre = 20 * 41 + 20;
  const double count = static_cast<double>(f.offsets[centre + 1] - f.offsets[centre]);
  EXPECT_GT(count, 0.7 * 30);
  EXPECT_LT(count, 1.3 * 30);
}

TEST(SurfaceFilterTest, AConstantIrradianceStaysConstantForAnyKAndAnyAlbedo) {
  SurfaceMesh s = grid(30, 0.02);
  std::mt19937 random(3);
  std::uniform_real_distribution<float> albedo(0.05f, 0.95f);
  for (long i = 0; i < s.albedo.rows(); ++i) s.albedo.row(i) << albedo(random), albedo(random), albedo(random);
  const Eigen::VectorXf L = radiance(s, [](long) { return Eigen::Vector3d(0.7, 0.2, 1.3); });
  for (const bool linear : {false, true}) {
    for (const int k : {1, 4, 16, 64, 400}) {
      Eigen::VectorXf out;
      surface_filter_apply(precompute(s, k, linear), L, out);
      EXPECT_LE((out - L).cwiseAbs().maxCoeff(), 1e-5f * L.cwiseAbs().maxCoeff()) << "k " << k << " linear " << linear;
    }
  }
}

TEST(SurfaceFilterTest, ALinearIrradianceOnAPlaneIsKeptAtInteriorPoints) {
  // A tilted plane (the grid's axes are not the world's, so the cell grid is not aligned with it).
  const Eigen::Vector3d u = Eigen::Vector3d(1, 0.3, 0.2).normalized();
  const Eigen::Vector3d v = u.cross(Eigen::Vector3d(0.1, 0.2, 1)).normalized();
  const double h = 0.01;
  const int n = 40;
  const SurfaceMesh s = grid(n, h, Eigen::Vector3d(0.3, -0.2, 0.1), u, v);
  // E = a + b·x + c·y in the plane's own coordinates (x = h·column, y = h·row).
  const auto E = [&](long i) {
    const double x = h * static_cast<double>(i % n), y = h * static_cast<double>(i / n);
    return Eigen::Vector3d(1 + 3 * x - 2 * y, 0.5 + 5 * y, 2 - 4 * x);
  };
  const Eigen::VectorXf L = radiance(s, E);
  for (const int k : {9, 25, 60}) {
    const SurfaceFilter f = precompute(s, k);
    Eigen::VectorXf out;
    surface_filter_apply(f, L, out);
    const int margin = static_cast<int>(std::ceil(f.radius / h)) + 1;
    int checked = 0;
    for (int y = margin; y < n - margin; ++y) {
      for (int x = margin; x < n - margin; ++x) {
        const long i = y * n + x;
        for (int c = 0; c < 3; ++c) {
          EXPECT_NEAR(out[3 * i + c], L[3 * i + c], 2e-5 * std::abs(L[3 * i + c]) + 1e-6) << "k " << k << " point " << i;
        }
        ++checked;
      }
    }
    EXPECT_GT(checked, 100) << "k " << k;
    // Near the border the neighbourhood is one-sided: a linear field is then not kept (so the
    // interior check above is not vacuous).
    EXPECT_GT(std::abs(out[0] - L[0]), 1e-3 * std::abs(L[0])) << "k " << k;
  }
}

TEST(SurfaceFilterTest, TheLinearFilterKeepsALinearIrradianceEverywhere) {
  // The local linear fit keeps a plane's field also where the neighbourhood is one-sided (the
  // borders and corners, where the mean is biased), and on a tilted plane.
  const Eigen::Vector3d u = Eigen::Vector3d(1, 0.3, 0.2).normalized();
  const Eigen::Vector3d v = u.cross(Eigen::Vector3d(0.1, 0.2, 1)).normalized();
  const double h = 0.01;
  const int n = 30;
  const SurfaceMesh s = grid(n, h, Eigen::Vector3d(0.3, -0.2, 0.1), u, v);
  const Eigen::VectorXf L = radiance(s, [&](long i) {
    const double x = h * static_cast<double>(i % n), y = h * static_cast<double>(i / n);
    return Eigen::Vector3d(1 + 3 * x - 2 * y, 0.5 + 5 * y, 2 - 4 * x);
  });
  for (const int k : {9, 25, 60}) {
    Eigen::VectorXf out;
    surface_filter_apply(precompute(s, k, true), L, out);
    for (long i = 0; i < L.size(); ++i) {
      ASSERT_NEAR(out[i], L[i], 1e-4 * std::abs(L[i]) + 1e-6) << "k " << k << " value " << i;
    }
  }
}

TEST(SurfaceFilterTest, TheTwoSidesOfAFoldDoNotMix) {
  // A floor (normal +y) and a wall (normal +x) meeting along the z axis, each with its own
  // vertices at the shared edge, lit with different constant irradiances.
  const SurfaceMesh floor = grid(20, 0.01, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX());
  const SurfaceMesh wall = grid(20, 0.01, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ());
  ASSERT_NEAR(floor.normals(0, 1), 1.0f, 1e-6f);
  ASSERT_NEAR(wall.normals(0, 0), 1.0f, 1e-6f);
  SurfaceMesh s;
  s.vertices.resize(800, 3);
  s.vertices << floor.vertices, wall.vertices;
  s.normals.resize(800, 3);
  s.normals << floor.normals, wall.normals;
  s.albedo.resize(800, 3);
  s.albedo << floor.albedo, wall.albedo;
  s.faces.resize(floor.faces.rows() * 2, 3);
  s.faces << floor.faces, (wall.faces.array() + 400).matrix();
  const Eigen::VectorXf L = radiance(s, [](long i) { return Eigen::Vector3d::Constant(i < 400 ? 1.0 : 5.0); });
  for (const bool linear : {false, true}) {
    Eigen::VectorXf out;
    surface_filter_apply(precompute(s, 40, linear), L, out);
    EXPECT_LE((out - L).cwiseAbs().maxCoeff(), 1e-5f * 5 * 0.5f) << "linear " << linear;
  }
}

TEST(SurfaceFilterTest, AnAlbedoBoundaryDoesNotBleed) {
  // Left half red, right half green under one constant irradiance: the radiance steps at the
  // boundary and stays stepped (a filter of the radiance itself would blur it).
  SurfaceMesh s = grid(30, 0.01);
  for (long i = 0; i < s.albedo.rows(); ++i) {
    if (i % 30 < 15) {
      s.albedo.row(i) << 0.63f, 0.065f, 0.05f;
    } else {
      s.albedo.row(i) << 0.14f, 0.45f, 0.091f;
    }
  }
  const Eigen::VectorXf L = radiance(s, [](long) { return Eigen::Vector3d::Ones(); });
  Eigen::VectorXf out;
  surface_filter_apply(precompute(s, 30), L, out);
  EXPECT_LE((out - L).cwiseAbs().maxCoeff(), 1e-5f);
  // A channel whose albedo is 0 at a point: that point reflects nothing there and carries no
  // irradiance estimate for its neighbours.
  s.albedo(0, 2) = 0;
  const Eigen::VectorXf L0 = radiance(s, [](long) { return Eigen::Vector3d::Ones(); });
  surface_filter_apply(precompute(s, 30), L0, out);
  EXPECT_EQ(out[2], 0.0f);
  EXPECT_LE((out - L0).cwiseAbs().maxCoeff(), 1e-5f);
}

TEST(SurfaceFilterTest, ANoisyConstantFieldsVarianceFallsAsOneOverK) {
  // Irradiance 1 + independent noise of standard deviation s per point and channel. A normalised
  // weighted mean has variance s² Σw² / (Σw)²; for the shifted Gaussian over a disc of k points
  // that is s² / (0.601 k) (∫w = 0.29700 πr², ∫w² = 0.14672 πr²; surface_filter.h).
  const int n = 200;
  const SurfaceMesh s = grid(n, 0.005);
  std::mt19937 random(11);
  std::normal_distribution<double> noise(0, 0.2);
  Eigen::VectorXf L(3 * n * n);
  for (long i = 0; i < L.size(); ++i) L[i] = static_cast<float>(0.5 * (1 + noise(random)));
  double previous = 0;
  for (const int k : {8, 32, 128}) {
    const SurfaceFilter f = precompute(s, k);
    Eigen::VectorXf out;
    surface_filter_apply(f, L, out);
    const int margin = static_cast<int>(std::ceil(f.radius / 0.005)) + 1;
    double sum = 0, sum2 = 0;
    long count = 0;
    for (int y = margin; y < n - margin; ++y) {
      for (int x = margin; x < n - margin; ++x) {
        for (int c = 0; c < 3; ++c) {
          const double e = out[3 * (y * n + x) + c] / 0.5;  // the irradiance
          sum += e;
          sum2 += e * e;
          ++count;
        }
      }
    }
    const double mean = sum / count;
    const double variance = sum2 / count - mean * mean;
    EXPECT_NEAR(mean, 1.0, 0.01) << "k " << k;
    const double expected = 0.2 * 0.2 / (0.601 * k);
    EXPECT_NEAR(variance / expected, 1.0, 0.25) << "k " << k;
    if (previous > 0) {
      EXPECT_NEAR(previous / variance, 4.0, 1.0) << "k " << k << ": 4 times the neighbours";
    }
    previous = variance;
  }
}

TEST(SurfaceFilterTest, FilteringAFewPointsFromTheirSupportEqualsFilteringTheFrame) {
  SurfaceMesh s = grid(25, 0.01);
  std::mt19937 random(5);
  std::uniform_real_distribution<float> uniform(0.05f, 0.95f);
  for (long i = 0; i < s.albedo.rows(); ++i) s.albedo.row(i) << uniform(random), uniform(random), uniform(random);
  Eigen::VectorXf L(3 * s.vertices.rows());
  for (long i = 0; i < L.size(); ++i) L[i] = uniform(random);
  const std::vector<int> points{0, 312, 77, 600, 312};
  for (const bool linear : {false, true}) {
    const SurfaceFilter f = precompute(s, 20, linear);
    Eigen::VectorXf whole, few;
    surface_filter_apply(f, L, whole);
    const std::vector<int> support = surface_filter_support(f, points);
    ASSERT_TRUE(std::is_sorted(support.begin(), support.end()));
    EXPECT_LT(support.size(), static_cast<size_t>(s.vertices.rows()) / 2);
    Eigen::VectorXf values(3 * support.size());
    for (size_t q = 0; q < support.size(); ++q) values.segment<3>(3 * static_cast<long>(q)) = L.segment<3>(3 * support[q]);
    surface_filter_apply_at(f, points, support, values, few);
    for (size_t p = 0; p < points.size(); ++p) {
      EXPECT_EQ(Eigen::Vector3f(few.segment<3>(3 * static_cast<long>(p))), Eigen::Vector3f(whole.segment<3>(3 * points[p])))
          << "point " << points[p] << " linear " << linear;
    }
  }
}

TEST(SurfaceFilterTest, OffLeavesTheFrameAndBadOptionsAreNamed) {
  const SurfaceMesh s = grid(5, 0.1);
  auto off = surface_filter_precompute(s, {});
  ASSERT_TRUE(off.ok());
  EXPECT_FALSE(off->enabled());
  const Eigen::VectorXf L = Eigen::VectorXf::LinSpaced(75, 0, 1);
  Eigen::VectorXf out;
  surface_filter_apply(*off, L, out);
  EXPECT_EQ(out, L);

  auto negative = surface_filter_precompute(s, {-1, 0.9, false}, "training.filter");
  ASSERT_FALSE(negative.ok());
  EXPECT_EQ(negative.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(negative.error().message.find("training.filter.neighbours"), std::string::npos) << negative.error().message;
  EXPECT_NE(negative.error().message.find("-1"), std::string::npos) << negative.error().message;
  for (const double cosine : {-1.0, 1.5, std::nan("")}) {
    auto bad = surface_filter_precompute(s, {8, cosine, false}, "filter");
    ASSERT_FALSE(bad.ok()) << cosine;
    EXPECT_NE(bad.error().message.find("filter.min_normal_cosine"), std::string::npos) << bad.error().message;
  }
}

}  // namespace
}  // namespace animspace::illumination
