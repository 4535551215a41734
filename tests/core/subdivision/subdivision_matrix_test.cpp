// The subdivision matrix against the schemes' own rules worked by hand (Loop 1987; Catmull &
// Clark 1978) and against invariants any affine refinement keeps.
#include "core/subdivision/subdivision_matrix.h"

#include <cmath>
#include <map>
#include <utility>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/common/types.h"

namespace animspace::subdivision {
namespace {

// n × n vertices on the unit square, vertex (r, c) = r·n + c; each cell split along the same
// diagonal, so every interior vertex has valence 6 (a regular Loop vertex).
FaceMatrix triangle_grid(int n) {
  FaceMatrix faces(2 * (n - 1) * (n - 1), 3);
  int f = 0;
  for (int r = 0; r + 1 < n; ++r) {
    for (int c = 0; c + 1 < n; ++c) {
      const int v00 = r * n + c, v01 = v00 + 1, v10 = v00 + n, v11 = v10 + 1;
      faces.row(f++) << v00, v01, v11;
      faces.row(f++) << v00, v11, v10;
    }
  }
  return faces;
}

// The same grid as quads (every interior vertex has valence 4: a regular Catmull–Clark vertex).
PolygonTopology quad_grid(int n) {
  PolygonTopology topology;
  topology.vertex_count = n * n;
  for (int r = 0; r + 1 < n; ++r) {
    for (int c = 0; c + 1 < n; ++c) {
      const int v00 = r * n + c;
      topology.face_sizes.push_back(4);
      for (const int v : {v00, v00 + 1, v00 + n + 1, v00 + n}) topology.face_indices.push_back(v);
    }
  }
  return topology;
}

// A closed triangle mesh with valence-5 (extraordinary) vertices everywhere.
FaceMatrix icosahedron_faces() {
  FaceMatrix faces(20, 3);
  faces << 0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9, 4, 3,
      4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1;
  return faces;
}

std::map<int32_t, double> row_of(const SparseRows& A, int row) {
  std::map<int32_t, double> entries;
  for (SparseRows::InnerIterator it(A, row); it; ++it) {
    if (it.value() != 0) entries[it.col()] = it.value();
  }
  return entries;
}

// The refined vertex whose row is supported exactly on `columns` and has weight `weight` on
// `columns[0]`, or -1.
int find_row(const SparseRows& A, const std::vector<int32_t>& columns, double weight) {
  for (int i = 0; i < A.rows(); ++i) {
    const auto entries = row_of(A, i);
    if (entries.size() != columns.size()) continue;
    bool match = true;
    for (const int32_t c : columns) match = match && entries.contains(c);
    if (match && std::abs(entries.at(columns[0]) - weight) < 1e-12) return i;
  }
  return -1;
}

SubdivisionMatrices build(const PolygonTopology& topology, int levels, Scheme scheme = Scheme::kAuto) {
  SubdivisionOptions options;
  options.levels = levels;
  options.scheme = scheme;
  auto matrices = subdivision_matrices(topology, options);
  EXPECT_TRUE(matrices.ok()) << matrices.error().message;
  return std::move(*matrices);
}

TEST(SubdivisionMatrix, LoopRegularVertexAndEdgeStencilsAreLoopsRules) {
  // Interior vertex 12 of a 5 × 5 grid: valence 6, β = (1/n)(5/8 − (3/8 + ¼ cos(2π/n))²) = 1/16,
  // so its vertex point keeps 1 − 6β = 10/16 and each neighbour weighs 1/16.
  const int n = 5;
  const SubdivisionMatrices m = build(triangle_topology(triangle_grid(n), n * n), 1);
  EXPECT_EQ(m.scheme, Scheme::kLoop);
  const int centre = 2 * n + 2;
  const std::vector<int32_t> ring{centre - 1, centre + 1, centre - n, centre + n, centre - n - 1, centre + n + 1};
  std::vector<int32_t> support{centre};
  support.insert(support.end(), ring.begin(), ring.end());
  const int vertex_point = find_row(m.S, support, 10.0 / 16);
  ASSERT_GE(vertex_point, 0) << "no refined vertex with Loop's valence-6 vertex rule";
  const auto entries = row_of(m.S, vertex_point);
  EXPECT_NEAR(entries.at(centre), 10.0 / 16, 1e-15);
  for (const int32_t v : ring) EXPECT_NEAR(entries.at(v), 1.0 / 16, 1e-15) << "neighbour " << v;

  // The interior edge (centre, centre + 1) lies on faces (centre, centre+1, centre+n+1) and
  // (centre−n, centre+1, centre) (the cell below, split along its diagonal): its edge point is
  // 3/8 of each end and 1/8 of each opposite vertex.
  const int edge_point = find_row(m.S, {centre, centre + 1, centre + n + 1, centre - n}, 3.0 / 8);
  ASSERT_GE(edge_point, 0) << "no refined vertex with Loop's interior edge rule";
  const auto edge = row_of(m.S, edge_point);
  EXPECT_NEAR(edge.at(centre + 1), 3.0 / 8, 1e-15);
  EXPECT_NEAR(edge.at(centre + n + 1), 1.0 / 8, 1e-15);
  EXPECT_NEAR(edge.at(centre - n), 1.0 / 8, 1e-15);
}

TEST(SubdivisionMatrix, CatmullClarkFaceEdgeAndVertexPointsAreTheRules) {
  const int n = 5;
  const SubdivisionMatrices m = build(quad_grid(n), 1);
  EXPECT_EQ(m.scheme, Scheme::kCatmullClark);
  const int centre = 2 * n + 2;
  // Face point of the cell (centre, centre+1, centre+n+1, centre+n): the average of its corners.
  const int face_point = find_row(m.S, {centre, centre + 1, centre + n + 1, centre + n}, 0.25);
  ASSERT_GE(face_point, 0);
  for (const auto& [v, w] : row_of(m.S, face_point)) EXPECT_NEAR(w, 0.25, 1e-15) << "corner " << v;
  // Edge point of (centre, centre+1): (v0 + v1 + f0 + f1)/4 with f the two face points, i.e. 3/8
  // of each end and 1/16 of the four other corners of the two faces.
  const int edge_point =
      find_row(m.S, {centre, centre + 1, centre + n, centre + n + 1, centre - n, centre - n + 1}, 3.0 / 8);
  ASSERT_GE(edge_point, 0);
  const auto edge = row_of(m.S, edge_point);
  EXPECT_NEAR(edge.at(centre + 1), 3.0 / 8, 1e-15);
  for (const int v : {centre + n, centre + n + 1, centre - n, centre - n + 1}) EXPECT_NEAR(edge.at(v), 1.0 / 16, 1e-15);
  // Vertex point of a valence-4 vertex: (Q + 2R + (n−3)S)/n = 9/16 of itself, 3/32 of each edge
  // neighbour and 1/64 of each diagonal one.
  std::vector<int32_t> support{centre, centre - 1, centre + 1, centre - n, centre + n,
                               centre - n - 1, centre - n + 1, centre + n - 1, centre + n + 1};
  const int vertex_point = find_row(m.S, support, 9.0 / 16);
  ASSERT_GE(vertex_point, 0);
  const auto vertex = row_of(m.S, vertex_point);
  for (const int v : {centre - 1, centre + 1, centre - n, centre + n}) EXPECT_NEAR(vertex.at(v), 3.0 / 32, 1e-15);
  for (const int v : {centre - n - 1, centre - n + 1, centre + n - 1, centre + n + 1}) {
    EXPECT_NEAR(vertex.at(v), 1.0 / 64, 1e-15);
  }
}

TEST(SubdivisionMatrix, RowsSumToOneAndTangentRowsToZero) {
  struct Case {
    const char* name;
    PolygonTopology topology;
  };
  PolygonTopology mixed = quad_grid(3);  // a quad grid with one quad replaced by two triangles
  mixed.face_sizes = {4, 4, 4, 3, 3};
  mixed.face_indices = {0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 7, 6, 4, 5, 8, 4, 8, 7};
  const Case cases[] = {{"icosahedron", triangle_topology(icosahedron_faces(), 12)},
                        {"triangle grid", triangle_topology(triangle_grid(4), 16)},
                        {"quad grid", quad_grid(4)},
                        {"mixed", mixed}};
  for (const Case& c : cases) {
    for (int levels = 1; levels <= 3; ++levels) {
      const SubdivisionMatrices m = build(c.topology, levels);
      const RefinedSize predicted = refined_size(c.topology, m.scheme, levels);
      EXPECT_EQ(m.S.rows(), predicted.vertices) << c.name << " level " << levels;
      EXPECT_EQ(m.refined.face_count(), predicted.faces) << c.name << " level " << levels;
      const Eigen::VectorXd sums = m.S * Eigen::VectorXd::Ones(m.S.cols());
      const Eigen::VectorXd du = m.tangent_u * Eigen::VectorXd::Ones(m.S.cols());
      const Eigen::VectorXd dv = m.tangent_v * Eigen::VectorXd::Ones(m.S.cols());
      EXPECT_LT((sums.array() - 1).abs().maxCoeff(), 1e-13) << c.name << " level " << levels;
      EXPECT_LT(du.cwiseAbs().maxCoeff(), 1e-12) << c.name << " level " << levels;
      EXPECT_LT(dv.cwiseAbs().maxCoeff(), 1e-12) << c.name << " level " << levels;
    }
  }
}

TEST(SubdivisionMatrix, APlaneSubdividesToAPlane) {
  // A tilted plane n·x = d, sampled on a jittered grid: every refined vertex (an affine
  // combination) and every limit tangent (a combination with weights summing to 0) stays in it.
  const int n = 6;
  const Eigen::Vector3d normal = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
  const Eigen::Vector3d a = normal.unitOrthogonal(), b = normal.cross(a);
  const double d = 2.5;
  Eigen::MatrixX3d points(n * n, 3);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const double x = c + 0.3 * std::sin(7.0 * r + c), y = r + 0.3 * std::cos(3.0 * c - r);
      points.row(r * n + c) = (d * normal + x * a + y * b).transpose();
    }
  }
  for (const PolygonTopology& topology : {triangle_topology(triangle_grid(n), n * n), quad_grid(n)}) {
    const SubdivisionMatrices m = build(topology, 2);
    const Eigen::MatrixX3d refined = m.S * points;
    EXPECT_LT(((refined * normal).array() - d).abs().maxCoeff(), 1e-12);
    EXPECT_LT((m.tangent_u * points * normal).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((m.tangent_v * points * normal).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(SubdivisionMatrix, RefusesBadLevelsBadFacesAndTooManyVertices) {
  const PolygonTopology ico = triangle_topology(icosahedron_faces(), 12);
  SubdivisionOptions options;
  for (const int levels : {0, -1, kMaxLevels + 1}) {
    options.levels = levels;
    auto m = subdivision_matrices(ico, options);
    ASSERT_FALSE(m.ok());
    EXPECT_EQ(m.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(m.error().message.find("levels"), std::string::npos) << m.error().message;
  }
  // Loop refuses a quad rather than guessing.
  options.levels = 1;
  options.scheme = Scheme::kLoop;
  auto loop = subdivision_matrices(quad_grid(3), options);
  ASSERT_FALSE(loop.ok());
  EXPECT_NE(loop.error().message.find("face 0 has 4 corners"), std::string::npos) << loop.error().message;
  // 12 vertices, 30 edges, 20 faces: level 2 has 12 + 30 + 120 = 162 vertices (icosphere counts).
  options.scheme = Scheme::kAuto;
  options.levels = 2;
  options.max_vertices = 161;
  auto big = subdivision_matrices(ico, options);
  ASSERT_FALSE(big.ok());
  EXPECT_EQ(big.error().code, ErrorCode::kResourceExhausted);
  EXPECT_NE(big.error().message.find("162 vertices"), std::string::npos) << big.error().message;
  options.max_vertices = 162;
  EXPECT_TRUE(subdivision_matrices(ico, options).ok());
  // A face outside the vertex range, and a degenerate one, name the face.
  PolygonTopology bad = ico;
  bad.face_indices[5] = 12;
  auto outside = subdivision_matrices(bad, options);
  ASSERT_FALSE(outside.ok());
  EXPECT_NE(outside.error().message.find("face 1"), std::string::npos) << outside.error().message;
  bad = ico;
  bad.face_indices[4] = bad.face_indices[3];
  auto degenerate = subdivision_matrices(bad, options);
  ASSERT_FALSE(degenerate.ok());
  EXPECT_NE(degenerate.error().message.find("face 1: repeats"), std::string::npos) << degenerate.error().message;
}

}  // namespace
}  // namespace animspace::subdivision
