#include "core/lod/surface_distance.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::lod {
namespace {

using Eigen::Vector3d;

// Independent reference: the minimum over a dense barycentric grid of the triangle (N + 1)(N + 2)/2
// samples; every point of the triangle is within (longest edge)/N of a sample.
double sampled_distance(const Vector3d& q, const Vector3d& a, const Vector3d& b, const Vector3d& c, int n) {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; i + j <= n; ++j) {
      const double s = static_cast<double>(i) / n;
      const double t = static_cast<double>(j) / n;
      const Vector3d p = (1 - s - t) * a + s * b + t * c;
      best = std::min(best, (q - p).norm());
    }
  }
  return best;
}

double longest_edge(const Vector3d& a, const Vector3d& b, const Vector3d& c) {
  return std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
}

Vector3d random_vector(std::mt19937_64& engine, double scale) {
  std::normal_distribution<double> normal;
  return scale * Vector3d(normal(engine), normal(engine), normal(engine));
}

// A subdivided icosahedron on the unit sphere: 20 · 4^levels triangles.
std::pair<Points3d, FaceMatrix> icosphere(int levels) {
  const double phi = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vector3d> vertices = {{-1, phi, 0}, {1, phi, 0},  {-1, -phi, 0}, {1, -phi, 0},
                                    {0, -1, phi}, {0, 1, phi},  {0, -1, -phi}, {0, 1, -phi},
                                    {phi, 0, -1}, {phi, 0, 1},  {-phi, 0, -1}, {-phi, 0, 1}};
  for (auto& v : vertices) v.normalize();
  std::vector<std::array<int, 3>> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                           {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                           {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                           {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> midpoints;
    auto midpoint = [&](int i, int j) {
      const auto key = std::minmax(i, j);
      const auto found = midpoints.find(key);
      if (found != midpoints.end()) return found->second;
      vertices.push_back((vertices[static_cast<size_t>(i)] + vertices[static_cast<size_t>(j)]).normalized());
      const int index = static_cast<int>(vertices.size() - 1);
      midpoints.emplace(key, index);
      return index;
    };
    std::vector<std::array<int, 3>> finer;
    for (const auto& f : faces) {
      const int ab = midpoint(f[0], f[1]);
      const int bc = midpoint(f[1], f[2]);
      const int ca = midpoint(f[2], f[0]);
      finer.push_back({f[0], ab, ca});
      finer.push_back({f[1], bc, ab});
      finer.push_back({f[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    faces = std::move(finer);
  }
  Points3d points(static_cast<Eigen::Index>(vertices.size()), 3);
  for (size_t v = 0; v < vertices.size(); ++v) points.row(static_cast<Eigen::Index>(v)) = vertices[v].transpose();
  FaceMatrix face_matrix(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) {
    face_matrix.row(static_cast<Eigen::Index>(f)) << faces[f][0], faces[f][1], faces[f][2];
  }
  return {points, face_matrix};
}

// `count` triangles with random corners around random centres: a mix of small, large, sliver and
// degenerate (segment, point) triangles.
std::pair<Points3d, FaceMatrix> triangle_soup(int count, uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::uniform_real_distribution<double> uniform(0, 1);
  Points3d points(3 * count, 3);
  FaceMatrix faces(count, 3);
  for (int f = 0; f < count; ++f) {
    const Vector3d centre = random_vector(engine, 1.0);
    const double size = f % 17 == 0 ? 1.5 : 0.02 + 0.2 * uniform(engine);
    Vector3d a = centre + random_vector(engine, size);
    Vector3d b = centre + random_vector(engine, size);
    Vector3d c = centre + random_vector(engine, size);
    if (f % 13 == 0) c = a + 0.37 * (b - a);      // a segment
    if (f % 29 == 0) b = c = a;                   // a point
    if (f % 11 == 0) c = 0.5 * (a + b) + Vector3d(0, 0, 1e-9);  // a sliver
    if (f % 7 == 0) c = 0.4 * a + 0.6 * b + random_vector(engine, 1e-7 * size);  // a milder one
    points.row(3 * f) = a.transpose();
    points.row(3 * f + 1) = b.transpose();
    points.row(3 * f + 2) = c.transpose();
    faces.row(f) << 3 * f, 3 * f + 1, 3 * f + 2;
  }
  return {points, faces};
}

double brute_force(const Points3d& points, const FaceMatrix& faces, const Vector3d& q) {
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    best = std::min(best, point_triangle_distance(q, points.row(faces(f, 0)).transpose(),
                                                  points.row(faces(f, 1)).transpose(),
                                                  points.row(faces(f, 2)).transpose()));
  }
  return best;
}

// Queries in and around the bounding box, near the surface and far away.
std::vector<Vector3d> queries_for(const Points3d& points, const FaceMatrix& faces, int count, uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::uniform_real_distribution<double> uniform(0, 1);
  const Vector3d lo = points.colwise().minCoeff().transpose();
  const Vector3d hi = points.colwise().maxCoeff().transpose();
  const double size = std::max(1e-3, (hi - lo).norm());
  std::vector<Vector3d> queries;
  for (int i = 0; i < count; ++i) {
    switch (i % 4) {
      case 0: {  // uniform in the box, slightly enlarged
        const Vector3d r(uniform(engine), uniform(engine), uniform(engine));
        queries.push_back(lo - 0.1 * size * Vector3d::Ones() + (r.array() * (hi - lo + 0.2 * size * Vector3d::Ones()).array()).matrix());
        break;
      }
      case 1: {  // near a random triangle
        const Eigen::Index f = static_cast<Eigen::Index>(uniform(engine) * static_cast<double>(faces.rows())) %
                               faces.rows();
        const double s = uniform(engine);
        const double t = uniform(engine) * (1 - s);
        const Vector3d p = (1 - s - t) * points.row(faces(f, 0)).transpose() +
                           s * points.row(faces(f, 1)).transpose() + t * points.row(faces(f, 2)).transpose();
        queries.push_back(p + random_vector(engine, 0.01 * size));
        break;
      }
      case 2:  // far outside the box
        queries.push_back(0.5 * (lo + hi) + random_vector(engine, 50 * size));
        break;
      default:  // just outside the box along a face
        queries.push_back(0.5 * (lo + hi) + random_vector(engine, 0.8 * size));
        break;
    }
  }
  return queries;
}

void expect_matches_brute_force(const Points3d& points, const FaceMatrix& faces, int query_count, uint64_t seed) {
  const SurfaceDistance surface(points, faces);
  for (const Vector3d& q : queries_for(points, faces, query_count, seed)) {
    const double expected = brute_force(points, faces, q);
    ASSERT_NEAR(surface.distance(q), expected, 1e-12) << "query " << q.transpose();
  }
}

// --- point_triangle_distance ---

TEST(PointTriangleDistanceTest, AboveTheInteriorIsTheHeight) {
  const Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({0.2, 0.3, 0.7}, a, b, c), 0.7);
  EXPECT_DOUBLE_EQ(point_triangle_distance({0.2, 0.3, -2.5}, a, b, c), 2.5);
  EXPECT_EQ(point_triangle_distance({0.2, 0.3, 0.0}, a, b, c), 0.0);
  EXPECT_EQ(point_triangle_distance(b, a, b, c), 0.0);
  // A tilted triangle: the plane x + y + z = 1, the point above its centroid.
  const Vector3d centroid(1.0 / 3, 1.0 / 3, 1.0 / 3);
  const Vector3d n = Vector3d(1, 1, 1).normalized();
  EXPECT_NEAR(point_triangle_distance(centroid + 0.25 * n, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}), 0.25, 1e-15);
}

TEST(PointTriangleDistanceTest, NearestOnAnEdgeOrAVertex) {
  const Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  // Edge ab at (0.5, 0, 0).
  EXPECT_DOUBLE_EQ(point_triangle_distance({0.5, -1, 2}, a, b, c), std::sqrt(5.0));
  // Edge ca at (0, 0.25, 0).
  EXPECT_DOUBLE_EQ(point_triangle_distance({-3, 0.25, 4}, a, b, c), 5.0);
  // Hypotenuse bc at (0.5, 0.5, 0).
  EXPECT_DOUBLE_EQ(point_triangle_distance({1, 1, 0}, a, b, c), std::sqrt(0.5));
  EXPECT_DOUBLE_EQ(point_triangle_distance({1, 1, 1}, a, b, c), std::sqrt(1.5));
  // Vertices.
  EXPECT_DOUBLE_EQ(point_triangle_distance({-1, -2, 3}, a, b, c), std::sqrt(14.0));
  EXPECT_DOUBLE_EQ(point_triangle_distance({2, -1, 0}, a, b, c), std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(point_triangle_distance({-1, 3, 0}, a, b, c), std::sqrt(5.0));
  // An obtuse triangle: a point beyond both short edges, in the vertex region of the obtuse
  // corner (0, 0.1, 0), and one below the middle of the long edge.
  const Vector3d p(-1, 0, 0), r(0, 0.1, 0), s(1, 0, 0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, 2, 0}, p, r, s), 1.9);
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, -1, 0}, p, r, s), 1.0);
  // Orientation does not matter.
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, 2, 0}, p, s, r), 1.9);
  EXPECT_DOUBLE_EQ(point_triangle_distance({-3, 0.25, 4}, a, c, b), 5.0);
}

TEST(PointTriangleDistanceTest, DegenerateTriangles) {
  // Three collinear corners: a segment from 0 to 2 on the x axis.
  const Vector3d a(0, 0, 0), b(1, 0, 0), c(2, 0, 0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({1, 1, 0}, a, b, c), 1.0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({1.7, 0, -3}, a, b, c), 3.0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({3, 0, 0}, a, b, c), 1.0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({-1, 0, 1}, a, b, c), std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(point_triangle_distance({3, 0, 0}, c, a, b), 1.0);
  // Two equal corners.
  EXPECT_DOUBLE_EQ(point_triangle_distance({1, 0, 1}, {0, 0, 0}, {0, 0, 0}, {0, 0, 2}), 1.0);
  EXPECT_DOUBLE_EQ(point_triangle_distance({0, 0, 5}, {0, 0, 2}, {0, 0, 0}, {0, 0, 0}), 3.0);
  // A point.
  const Vector3d p(1, 2, 3);
  EXPECT_DOUBLE_EQ(point_triangle_distance({1, 2, 5}, p, p, p), 2.0);
  EXPECT_EQ(point_triangle_distance(p, p, p, p), 0.0);
}

TEST(PointTriangleDistanceTest, AgreesWithDenseSamplingOfRandomTriangles) {
  std::mt19937_64 engine(7);
  constexpr int kSamples = 300;
  for (int trial = 0; trial < 200; ++trial) {
    const Vector3d a = random_vector(engine, 1), b = random_vector(engine, 1);
    Vector3d c = random_vector(engine, 1);
    if (trial % 10 == 0) c = 0.3 * a + 0.7 * b + random_vector(engine, 1e-7);  // a near-sliver
    const Vector3d q = (trial % 3 == 0 ? 0.3 : 2.0) * random_vector(engine, 1);
    const double exact = point_triangle_distance(q, a, b, c);
    const double sampled = sampled_distance(q, a, b, c, kSamples);
    // The samples are points of the triangle, so the exact distance is no larger, and the nearest
    // point is within the sampling spacing of a sample.
    EXPECT_LE(exact, sampled + 1e-12) << "trial " << trial;
    EXPECT_GE(exact, sampled - longest_edge(a, b, c) / kSamples - 1e-12) << "trial " << trial;
  }
}

TEST(PointTriangleDistanceTest, AgreesWithDenseSamplingNearTheTriangle) {
  // Points close to the surface, where region mistakes would show most.
  std::mt19937_64 engine(11);
  std::uniform_real_distribution<double> uniform(-0.2, 1.2);
  constexpr int kSamples = 400;
  const Vector3d a(0.1, -0.2, 0.05), b(1.3, 0.1, -0.2), c(0.4, 0.9, 0.3);
  for (int trial = 0; trial < 100; ++trial) {
    const double s = uniform(engine);
    const double t = uniform(engine);
    const Vector3d q = a + s * (b - a) + t * (c - a) + random_vector(engine, 0.01);
    const double exact = point_triangle_distance(q, a, b, c);
    const double sampled = sampled_distance(q, a, b, c, kSamples);
    EXPECT_LE(exact, sampled + 1e-12);
    EXPECT_GE(exact, sampled - longest_edge(a, b, c) / kSamples - 1e-12);
  }
}

TEST(PointTriangleDistanceTest, SliverLikeItsLongestEdge) {
  // A sliver 1e-12 wide: no point is further than that from its long edge.
  const Vector3d a(0, 0, 0), b(1, 0, 0), c(0.5, 1e-12, 0);
  std::mt19937_64 engine(3);
  for (int trial = 0; trial < 100; ++trial) {
    const Vector3d q = random_vector(engine, 1);
    const double segment = point_triangle_distance(q, a, b, b);
    EXPECT_NEAR(point_triangle_distance(q, a, b, c), segment, 2e-12);
  }
}

// --- SurfaceDistance ---

TEST(SurfaceDistanceTest, MatchesBruteForceOnASphere) {
  const auto [points, faces] = icosphere(3);  // 1280 triangles
  expect_matches_brute_force(points, faces, 2000, 1);
}

TEST(SurfaceDistanceTest, MatchesBruteForceOnATriangleSoup) {
  const auto [points, faces] = triangle_soup(600, 5);
  expect_matches_brute_force(points, faces, 2000, 2);
}

TEST(SurfaceDistanceTest, MatchesBruteForceOnAFlatAndAThinMesh) {
  // A planar grid (the box has zero thickness) and a long strip one triangle wide.
  constexpr int kN = 20;
  Points3d plane(kN * kN, 3);
  FaceMatrix plane_faces(2 * (kN - 1) * (kN - 1), 3);
  Eigen::Index f = 0;
  for (int i = 0; i < kN; ++i) {
    for (int j = 0; j < kN; ++j) plane.row(i * kN + j) << 0.1 * i, 0.1 * j + 0.01 * i, 0.0;
  }
  for (int i = 0; i + 1 < kN; ++i) {
    for (int j = 0; j + 1 < kN; ++j) {
      plane_faces.row(f++) << i * kN + j, (i + 1) * kN + j, i * kN + j + 1;
      plane_faces.row(f++) << (i + 1) * kN + j, (i + 1) * kN + j + 1, i * kN + j + 1;
    }
  }
  expect_matches_brute_force(plane, plane_faces, 1000, 3);

  constexpr int kLength = 300;
  Points3d strip(2 * kLength, 3);
  FaceMatrix strip_faces(2 * (kLength - 1), 3);
  for (int i = 0; i < kLength; ++i) {
    strip.row(2 * i) << i, 0, 0.001 * i;
    strip.row(2 * i + 1) << i, 0.5, 0.001 * i;
  }
  for (int i = 0; i + 1 < kLength; ++i) {
    strip_faces.row(2 * i) << 2 * i, 2 * i + 2, 2 * i + 1;
    strip_faces.row(2 * i + 1) << 2 * i + 2, 2 * i + 3, 2 * i + 1;
  }
  expect_matches_brute_force(strip, strip_faces, 1000, 4);
}

TEST(SurfaceDistanceTest, SingleAndDegenerateTriangles) {
  Points3d points(3, 3);
  points << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  FaceMatrix faces(1, 3);
  faces << 0, 1, 2;
  expect_matches_brute_force(points, faces, 400, 5);
  EXPECT_DOUBLE_EQ(SurfaceDistance(points, faces).distance({0.2, 0.2, 3}), 3.0);

  // Every triangle a single point: the box has no extent at all.
  Points3d point(1, 3);
  point << 1, 2, 3;
  FaceMatrix at_point(2, 3);
  at_point << 0, 0, 0, 0, 0, 0;
  const SurfaceDistance surface(point, at_point);
  EXPECT_DOUBLE_EQ(surface.distance({1, 2, 5}), 2.0);
  EXPECT_DOUBLE_EQ(surface.distance({-2, 6, 3}), 5.0);
  EXPECT_EQ(surface.distance({1, 2, 3}), 0.0);
}

TEST(SurfaceDistanceTest, IgnoresUnusedPointsAndHandlesNonFiniteQueries) {
  auto [points, faces] = icosphere(1);
  Points3d with_unused(points.rows() + 1, 3);
  with_unused << points, Eigen::RowVector3d(100, 100, 100);
  const SurfaceDistance surface(with_unused, faces);
  EXPECT_NEAR(surface.distance({0, 0, 0}), brute_force(points, faces, {0, 0, 0}), 1e-15);
  EXPECT_NEAR(surface.distance({100, 100, 100}), brute_force(points, faces, {100, 100, 100}), 1e-12);
  EXPECT_TRUE(std::isnan(surface.distance({std::nan(""), 0, 0})));
  EXPECT_EQ(surface.distance({std::numeric_limits<double>::infinity(), 0, 0}),
            std::numeric_limits<double>::infinity());
}

TEST(SurfaceDistanceTest, QueriesPerSecondOnTwentyThousandTriangles) {
  // Throughput on a 20480-triangle sphere, single thread, for queries near the surface (the LOD
  // benchmark's case) and uniformly in the box; reported, not asserted.
  const auto [points, faces] = icosphere(5);
  const auto start_build = std::chrono::steady_clock::now();
  const SurfaceDistance surface(points, faces);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_build).count();
  std::mt19937_64 engine(9);
  std::uniform_real_distribution<double> uniform(-1.1, 1.1);
  std::vector<Vector3d> near(200000), box(20000);
  for (auto& q : near) q = random_vector(engine, 1).normalized() * (1 + 0.01 * uniform(engine));
  for (auto& q : box) q = Vector3d(uniform(engine), uniform(engine), uniform(engine));
  for (const auto* set : {&near, &box}) {
    double checksum = 0;
    const auto start = std::chrono::steady_clock::now();
    for (const Vector3d& q : *set) checksum += surface.distance(q);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << (set == &near ? "near-surface" : "uniform-in-box") << " queries: "
              << static_cast<double>(set->size()) / seconds
              << " per second (grid built in " << build_s * 1e3 << " ms, checksum " << checksum << ")\n";
    EXPECT_GT(checksum, 0);
  }
  // Spot check against brute force.
  for (int i = 0; i < 50; ++i) {
    EXPECT_NEAR(surface.distance(near[static_cast<size_t>(i)]), brute_force(points, faces, near[static_cast<size_t>(i)]),
                1e-12);
    EXPECT_NEAR(surface.distance(box[static_cast<size_t>(i)]), brute_force(points, faces, box[static_cast<size_t>(i)]),
                1e-12);
  }
}

// --- distances_to_surface ---

TEST(SurfaceDistanceSummaryTest, MatchesBruteForceArithmetic) {
  const auto [points, faces] = triangle_soup(200, 8);
  const std::vector<Vector3d> list = queries_for(points, faces, 20000, 12);
  Points3d queries(static_cast<Eigen::Index>(list.size()), 3);
  for (size_t i = 0; i < list.size(); ++i) queries.row(static_cast<Eigen::Index>(i)) = list[i].transpose();

  double sum = 0;
  double max = 0;
  for (const Vector3d& q : list) {
    const double d = brute_force(points, faces, q);
    sum += d * d;
    max = std::max(max, d);
  }
  const SurfaceDistance surface(points, faces);
  const DistanceSummary summary = distances_to_surface(queries, surface);
  EXPECT_EQ(summary.count, static_cast<long>(list.size()));
  EXPECT_NEAR(summary.sum_of_squares, sum, 1e-12 * sum);
  EXPECT_NEAR(summary.rms, std::sqrt(sum / static_cast<double>(list.size())), 1e-12 * summary.rms);
  EXPECT_NEAR(summary.max, max, 1e-12);

  // Deterministic: the same bits on a second run (and whatever the number of threads).
  const DistanceSummary again = distances_to_surface(queries, surface);
  EXPECT_EQ(again.sum_of_squares, summary.sum_of_squares);
  EXPECT_EQ(again.rms, summary.rms);
  EXPECT_EQ(again.max, summary.max);
}

TEST(SurfaceDistanceSummaryTest, NoQueriesAndOneQuery) {
  const auto [points, faces] = icosphere(0);
  const SurfaceDistance surface(points, faces);
  const DistanceSummary none = distances_to_surface(Points3d(0, 3), surface);
  EXPECT_EQ(none.count, 0);
  EXPECT_EQ(none.rms, 0.0);
  EXPECT_EQ(none.max, 0.0);
  EXPECT_EQ(none.sum_of_squares, 0.0);

  Points3d one(1, 3);
  one << 0, 0, 5;
  const DistanceSummary single = distances_to_surface(one, surface);
  const double d = brute_force(points, faces, {0, 0, 5});
  EXPECT_EQ(single.count, 1);
  EXPECT_NEAR(single.rms, d, 1e-14);
  EXPECT_NEAR(single.max, d, 1e-14);
  EXPECT_NEAR(single.sum_of_squares, d * d, 1e-13);
}

}  // namespace
}  // namespace animspace::lod
