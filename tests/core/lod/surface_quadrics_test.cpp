// Quadric memory in normalised animation space (issue #26): a planar patch costs nothing, an open
// pyramid's apex quadric at a base corner is its hand-worked value, merging adds quadrics, and
// none of it depends on the dimension the surface is embedded in.
#include "core/lod/surface_quadrics.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include <Eigen/QR>

namespace animspace::lod {
namespace {

// A random orthonormal map R³ → Rⁿ: distances and areas are those of the 3-D points.
Eigen::MatrixXd embedding(int n, unsigned seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd m(n, 3);
  for (Eigen::Index i = 0; i < m.size(); ++i) m(i) = normal(random);
  return Eigen::HouseholderQR<Eigen::MatrixXd>(m).householderQ() * Eigen::MatrixXd::Identity(n, 3);
}

TEST(SurfaceQuadrics, PlanarPatchCostsNothingAnywhereInItsPlane) {
  // A 3 × 3 grid of points in the plane z = 0, 8 triangles, embedded in R⁷.
  Eigen::MatrixXd grid(3, 9);
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) grid.col(3 * j + i) = Eigen::Vector3d(i, 0.5 * j, 0);
  }
  FaceMatrix faces(8, 3);
  int f = 0;
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const int a = 3 * j + i;
      faces.row(f++) << a, a + 1, a + 4;
      faces.row(f++) << a, a + 4, a + 3;
    }
  }
  const Eigen::MatrixXd E = embedding(7, 1);
  const SurfaceQuadrics quadrics(E * grid, faces);
  // The centre (an interior vertex: no boundary lines) may move anywhere in the plane for free.
  for (int w = 0; w < 9; ++w) {
    EXPECT_NEAR(quadrics.error(4, E * grid.col(w)), 0, 1e-12) << "centre moved onto vertex " << w;
  }
  EXPECT_NEAR(quadrics.error(4, E * Eigen::Vector3d(7, -3, 0)), 0, 1e-12);
  // Off the plane by t, it costs t² times the area of its fan: six of the eight triangles, each
  // of area ½ · 1 · ½.
  const double t = 0.3;
  EXPECT_NEAR(quadrics.error(4, E * Eigen::Vector3d(1, 0.5, t)), t * t * 1.5, 1e-12);
  EXPECT_NEAR(quadrics.weight(4), 1.5, 1e-12);
}

TEST(SurfaceQuadrics, OpenPyramidApexAtABaseCornerIsItsHandWorkedCost) {
  // Apex (0, 0, h) over the square (±1, ±1, 0), four side faces, no base. A base corner lies on
  // its own two faces' planes and at 2h/√(1+h²) from each of the other two (planes h(x+1) − z = 0
  // and h(y+1) − z = 0 for the corner (1, 1, 0)); every face has area √(1+h²).
  // Q_apex(corner) = 2 √(1+h²) · 4h²/(1+h²) = 8h²/√(1+h²).
  const double h = 0.7;
  Eigen::MatrixXd points(3, 5);
  points.col(0) = Eigen::Vector3d(0, 0, h);
  points.col(1) = Eigen::Vector3d(1, 1, 0);
  points.col(2) = Eigen::Vector3d(-1, 1, 0);
  points.col(3) = Eigen::Vector3d(-1, -1, 0);
  points.col(4) = Eigen::Vector3d(1, -1, 0);
  FaceMatrix faces(4, 3);
  faces << 0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1;
  for (const int n : {3, 5, 12}) {
    const Eigen::MatrixXd E = embedding(n, static_cast<unsigned>(n));
    const SurfaceQuadrics quadrics(E * points, faces);
    EXPECT_EQ(quadrics.plane_count(0), 4) << "n = " << n;  // no boundary edge touches the apex
    EXPECT_NEAR(quadrics.error(0, E * points.col(1)), 8 * h * h / std::sqrt(1 + h * h), 1e-12) << "n = " << n;
    EXPECT_NEAR(quadrics.error(0, E * points.col(0)), 0, 1e-12) << "n = " << n;
  }
}

TEST(SurfaceQuadrics, BoundaryEdgesRememberTheirLine) {
  // One triangle: every edge is a boundary. Corner 0 has its face and its two edges' lines; a
  // point in the face's plane at distance d from edge 0–1's line (and on edge 0–2's line) costs
  // the line's weight |e|² times d².
  Eigen::MatrixXd points(3, 3);
  points << 0, 2, 0,  //
      0, 0, 1,        //
      0, 0, 0;
  FaceMatrix faces(1, 3);
  faces << 0, 1, 2;
  const SurfaceQuadrics quadrics(points, faces);
  EXPECT_EQ(quadrics.plane_count(0), 3);
  const double d = 0.25;
  EXPECT_NEAR(quadrics.error(0, Eigen::Vector3d(0, d, 0)), 4.0 * d * d, 1e-12);
  EXPECT_NEAR(quadrics.weight(0), 1.0 + 4.0 + 1.0, 1e-12);  // area 1, |e01|² = 4, |e02|² = 1
}

TEST(SurfaceQuadrics, MergingAddsTheQuadrics) {
  const double h = 0.4;
  Eigen::MatrixXd points(3, 5);
  points << 0, 1, -1, -1, 1,  //
      0, 1, 1, -1, -1,        //
      h, 0, 0, 0, 0;
  FaceMatrix faces(4, 3);
  faces << 0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1;
  SurfaceQuadrics quadrics(points, faces);
  std::mt19937 random(5);
  std::uniform_real_distribution<double> uniform(-2, 2);
  std::vector<Eigen::Vector3d> probes;
  std::vector<double> sums;
  for (int k = 0; k < 10; ++k) {
    probes.emplace_back(uniform(random), uniform(random), uniform(random));
    sums.push_back(quadrics.error(0, probes.back()) + quadrics.error(1, probes.back()));
  }
  const double weight = quadrics.weight(0) + quadrics.weight(1);
  quadrics.merge(0, 1);
  EXPECT_EQ(quadrics.plane_count(0), 0);
  EXPECT_NEAR(quadrics.weight(1), weight, 1e-12);
  for (size_t k = 0; k < probes.size(); ++k) EXPECT_NEAR(quadrics.error(1, probes[k]), sums[k], 1e-9);
}

}  // namespace
}  // namespace animspace::lod
