// Edges, adjacency, normals and bounding spheres against hand-worked cases and brute force.
#include <algorithm>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "core/geometry/bounding_sphere.h"
#include "core/geometry/edges.h"
#include "core/geometry/normals.h"

namespace animspace::geometry {
namespace {

FaceMatrix two_triangles_and_a_degenerate() {
  FaceMatrix F(3, 3);
  F << 0, 1, 2,  //
      2, 1, 3,   // shares edge (1, 2)
      4, 4, 0;   // degenerate: only edge (0, 4)
  return F;
}

TEST(EdgesTest, EachUndirectedEdgeOnceSortedWithoutDegenerateSelfEdges) {
  const auto edges = unique_edges(two_triangles_and_a_degenerate());
  const std::vector<std::pair<int32_t, int32_t>> expected = {{0, 1}, {0, 2}, {0, 4}, {1, 2}, {1, 3}, {2, 3}};
  EXPECT_EQ(edges, expected);
}

TEST(EdgesTest, AdjacencyMatchesBruteForceOnARandomMesh) {
  std::mt19937 engine(5);
  std::uniform_int_distribution<int32_t> vertex(0, 39);
  FaceMatrix F(200, 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) F.row(f) << vertex(engine), vertex(engine), vertex(engine);
  const int32_t V = 45;  // five vertices in no face
  const Adjacency adjacency = vertex_adjacency(V, F);
  ASSERT_EQ(adjacency.offsets.size(), static_cast<size_t>(V) + 1);
  for (int32_t i = 0; i < V; ++i) {
    std::set<int32_t> expected;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      for (int c = 0; c < 3; ++c) {
        if (F(f, c) != i) continue;
        for (int d = 0; d < 3; ++d) {
          if (F(f, d) != i) expected.insert(F(f, d));
        }
      }
    }
    const std::vector<int32_t> got(adjacency.neighbours.begin() + adjacency.begin(i),
                                   adjacency.neighbours.begin() + adjacency.end(i));
    EXPECT_EQ(got, std::vector<int32_t>(expected.begin(), expected.end())) << "vertex " << i;
  }
}

TEST(NormalsTest, AreaWeightedNormalsOfAFold) {
  // Two triangles sharing edge (0, 1): area 0.5 with normal +z, area 1 with normal −y.
  Eigen::MatrixX3d V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, -2;
  FaceMatrix F(2, 3);
  F << 0, 1, 2, 1, 0, 3;
  const Eigen::MatrixX3d N = area_weighted_normals(V, F);
  const Eigen::Vector3d shared = Eigen::Vector3d(0, -2, 1).normalized();  // 2 · Σ area · normal
  EXPECT_TRUE(N.row(0).transpose().isApprox(shared, 1e-12));
  EXPECT_TRUE(N.row(1).transpose().isApprox(shared, 1e-12));
  EXPECT_TRUE(N.row(2).transpose().isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  EXPECT_TRUE(N.row(3).transpose().isApprox(-Eigen::Vector3d::UnitY(), 1e-12));
}

TEST(NormalsTest, FloatPointsGiveTheDoubleResultUpToFloatRoundingAndIsolatedVerticesZero) {
  PointMatrix V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, -2, 7, 7, 7;  // vertex 4 is in no face
  FaceMatrix F(2, 3);
  F << 0, 1, 2, 1, 0, 3;
  const PointMatrix N = area_weighted_normals(V, F);
  const Eigen::MatrixX3d reference = area_weighted_normals(V.cast<double>(), F);
  EXPECT_LT((N.cast<double>() - reference).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_EQ(N.row(4).norm(), 0.0f);
}

TEST(BoundingSphereTest, BoxCentreAndFarthestPoint) {
  Eigen::MatrixX3d P(3, 3);
  P << -1, 0, 0,  //
      3, 2, 0,    //
      1, -2, 4;
  const BoundingSphere sphere = bounding_sphere(P);
  EXPECT_TRUE(sphere.centre.isApprox(Eigen::Vector3d(1, 0, 2)));
  // Distances from (1, 0, 2): √8, √12, √8.
  EXPECT_DOUBLE_EQ(sphere.radius, std::sqrt(12.0));
  for (Eigen::Index i = 0; i < P.rows(); ++i) EXPECT_LE((P.row(i).transpose() - sphere.centre).norm(), sphere.radius + 1e-12);
}

TEST(BoundingSphereTest, OnePointHasRadiusZeroAndNoPointsTheZeroSphere) {
  PointMatrix one(1, 3);
  one << 2, 3, 4;
  const BoundingSphere a = bounding_sphere(one);
  EXPECT_TRUE(a.centre.isApprox(Eigen::Vector3d(2, 3, 4)));
  EXPECT_EQ(a.radius, 0.0);
  const BoundingSphere none = bounding_sphere(PointMatrix(0, 3));
  EXPECT_EQ(none.radius, 0.0);
  EXPECT_EQ(none.centre, Eigen::Vector3d::Zero());
}

}  // namespace
}  // namespace animspace::geometry
