#include "core/illumination/surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace animspace::illumination {
namespace {

// The published Cornell box (https://www.graphics.cornell.edu/online/box/data.html), copied
// here independently of surface.cpp: millimetres, corners consecutive around each quad.
using QuadMm = std::array<Eigen::Vector3d, 4>;
const std::vector<QuadMm> kRoomQuads = {
    {{{552.8, 0, 0}, {0, 0, 0}, {0, 0, 559.2}, {549.6, 0, 559.2}}},                   // floor
    {{{556, 548.8, 0}, {556, 548.8, 559.2}, {0, 548.8, 559.2}, {0, 548.8, 0}}},       // ceiling
    {{{549.6, 0, 559.2}, {0, 0, 559.2}, {0, 548.8, 559.2}, {556, 548.8, 559.2}}},     // back
    {{{0, 0, 559.2}, {0, 0, 0}, {0, 548.8, 0}, {0, 548.8, 559.2}}},                   // right (green)
    {{{552.8, 0, 0}, {549.6, 0, 559.2}, {556, 548.8, 559.2}, {556, 548.8, 0}}},       // left (red)
};
// Each block: its top; the sides are the top's edges extruded to the floor.
const QuadMm kShortTop = {{{130, 165, 65}, {82, 165, 225}, {240, 165, 272}, {290, 165, 114}}};
const QuadMm kTallTop = {{{423, 330, 247}, {265, 330, 296}, {314, 330, 456}, {472, 330, 406}}};

double quad_area_m2(const QuadMm& q) { return 0.5e-6 * (q[2] - q[0]).cross(q[3] - q[1]).norm(); }

double published_area_m2() {
  double area = 0;
  for (const QuadMm& q : kRoomQuads) area += quad_area_m2(q);
  for (const QuadMm* top : {&kShortTop, &kTallTop}) {
    area += quad_area_m2(*top);
    const double height = (*top)[0].y();
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d a = (*top)[static_cast<size_t>(k)];
      const Eigen::Vector3d b = (*top)[static_cast<size_t>((k + 1) % 4)];
      area += 1e-6 * Eigen::Vector2d(b.x() - a.x(), b.z() - a.z()).norm() * height;
    }
  }
  return area;
}

Eigen::Vector3d block_centre_m(const QuadMm& top) {
  Eigen::Vector3d c = 0.25 * (top[0] + top[1] + top[2] + top[3]);
  c.y() *= 0.5;
  return 1e-3 * c;
}

// The connected components of the triangle graph: the scene's planar faces, each with its own
// vertices.
std::vector<std::vector<int>> components(const SurfaceMesh& mesh) {
  std::vector<int> parent(static_cast<size_t>(mesh.vertices.rows()));
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&parent](int v) {
    while (parent[static_cast<size_t>(v)] != v) v = parent[static_cast<size_t>(v)];
    return v;
  };
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    for (int k = 1; k < 3; ++k) parent[static_cast<size_t>(root(mesh.faces(f, k)))] = root(mesh.faces(f, 0));
  }
  std::vector<int> index_of(parent.size(), -1);
  std::vector<std::vector<int>> groups;
  for (int v = 0; v < static_cast<int>(parent.size()); ++v) {
    const int r = root(v);
    if (index_of[static_cast<size_t>(r)] < 0) {
      index_of[static_cast<size_t>(r)] = static_cast<int>(groups.size());
      groups.emplace_back();
    }
    groups[static_cast<size_t>(index_of[static_cast<size_t>(r)])].push_back(v);
  }
  return groups;
}

TEST(CornellBox, VertexCountIsNearTheTarget) {
  for (const int target : {2000, 10000, 100000}) {
    const SurfaceMesh mesh = cornell_box({target});
    EXPECT_NEAR(static_cast<double>(mesh.vertices.rows()), target, 0.03 * target) << "target " << target;
    EXPECT_EQ(mesh.normals.rows(), mesh.vertices.rows());
    EXPECT_EQ(mesh.albedo.rows(), mesh.vertices.rows());
    EXPECT_TRUE(check_surface(mesh, "cornell").ok());
  }
  // Below the minimum every face is one cell: 15 faces × 4 vertices, 2 triangles each.
  const SurfaceMesh tiny = cornell_box({1});
  EXPECT_EQ(tiny.vertices.rows(), 60);
  EXPECT_EQ(tiny.faces.rows(), 30);
}

TEST(CornellBox, TrianglesCoverThePublishedArea) {
  const SurfaceMesh mesh = cornell_box({20000});
  double area = 0;
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.faces(f, 0)).cast<double>();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.faces(f, 1)).cast<double>();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.faces(f, 2)).cast<double>();
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  EXPECT_NEAR(area, published_area_m2(), 1e-3 * published_area_m2());
}

TEST(CornellBox, BoundingBoxIsThePublishedRoom) {
  const SurfaceMesh mesh = cornell_box({5000});
  const Eigen::Vector3f low = mesh.vertices.colwise().minCoeff();
  const Eigen::Vector3f high = mesh.vertices.colwise().maxCoeff();
  EXPECT_TRUE(low.isZero(1e-7f)) << low.transpose();
  EXPECT_NEAR(high.x(), 0.556, 1e-6);
  EXPECT_NEAR(high.y(), 0.5488, 1e-6);
  EXPECT_NEAR(high.z(), 0.5592, 1e-6);
  const Box room = cornell_room();
  EXPECT_TRUE(room.min.isZero());
  EXPECT_TRUE(room.max.isApprox(Eigen::Vector3d(0.556, 0.5488, 0.5592), 1e-12));
}

TEST(CornellBox, FacesHaveOneNormalAndAlbedoFacingTheLitSide) {
  const SurfaceMesh mesh = cornell_box({8000});
  const std::vector<std::vector<int>> faces = components(mesh);
  ASSERT_EQ(faces.size(), 15u);  // 5 room faces, 5 per block
  const Eigen::Vector3d room_centre(0.278, 0.2744, 0.2796);
  const Eigen::Vector3d short_centre = block_centre_m(kShortTop);
  const Eigen::Vector3d tall_centre = block_centre_m(kTallTop);
  const Eigen::Vector3f white(0.73f, 0.71f, 0.68f);
  const Eigen::Vector3f red(0.63f, 0.065f, 0.05f);
  const Eigen::Vector3f green(0.14f, 0.45f, 0.091f);
  int room_faces = 0, short_faces = 0, tall_faces = 0, red_faces = 0, green_faces = 0;
  for (const std::vector<int>& face : faces) {
    EXPECT_GE(face.size(), 4u);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int v : face) centroid += mesh.vertices.row(v).cast<double>();
    centroid /= static_cast<double>(face.size());
    const Eigen::Vector3f n = mesh.normals.row(face[0]);
    const Eigen::Vector3f rho = mesh.albedo.row(face[0]);
    for (int v : face) {
      ASSERT_EQ(Eigen::Vector3f(mesh.normals.row(v)), n) << "vertex " << v;
      ASSERT_EQ(Eigen::Vector3f(mesh.albedo.row(v)), rho) << "vertex " << v;
    }
    EXPECT_NEAR(n.norm(), 1.0f, 1e-6f);
    const Eigen::Vector3d nd = n.cast<double>();
    // Room faces lie on the room's bounding box: their centroid is within 3 mm of a side.
    const Eigen::Vector3d box_max(0.556, 0.5488, 0.5592);
    const double to_box_side = std::min(centroid.minCoeff(), (box_max - centroid).minCoeff());
    if (to_box_side < 0.003) {
      ++room_faces;
      EXPECT_GT(nd.dot(room_centre - centroid), 0) << "room face at " << centroid.transpose();
      // Axis-aligned inwards, up to the red wall's 0.3° tilt.
      int axis = 0;
      (centroid - room_centre).cwiseAbs().cwiseQuotient(box_max).maxCoeff(&axis);
      EXPECT_GT(std::abs(nd[axis]), 0.9999) << centroid.transpose();
      if (centroid.x() < 0.003) {
        ++green_faces;
        EXPECT_EQ(rho, green);
      } else if (centroid.x() > 0.55) {
        ++red_faces;
        EXPECT_EQ(rho, red);
      } else {
        EXPECT_EQ(rho, white);
      }
    } else {
      const bool is_short = (centroid - short_centre).norm() < (centroid - tall_centre).norm();
      ++(is_short ? short_faces : tall_faces);
      const Eigen::Vector3d block_centre = is_short ? short_centre : tall_centre;
      EXPECT_GT(nd.dot(centroid - block_centre), 0) << "block face at " << centroid.transpose();
      EXPECT_EQ(rho, white);
      // No bottom face: nothing of a block faces down.
      EXPECT_GT(nd.y(), -1e-3);
    }
  }
  EXPECT_EQ(room_faces, 5);
  EXPECT_EQ(short_faces, 5);
  EXPECT_EQ(tall_faces, 5);
  EXPECT_EQ(red_faces, 1);
  EXPECT_EQ(green_faces, 1);
}

TEST(CornellBox, TrianglesAreCounterClockwiseSeenFromTheLitSide) {
  const SurfaceMesh mesh = cornell_box({3000});
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.faces(f, 0)).cast<double>();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.faces(f, 1)).cast<double>();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.faces(f, 2)).cast<double>();
    const Eigen::Vector3d cross = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d n = mesh.normals.row(mesh.faces(f, k)).cast<double>();
      ASSERT_GT(cross.dot(n), 0.99 * cross.norm()) << "triangle " << f;  // CCW and nearly in the plane
    }
  }
}

TEST(CornellBox, CellsAreNearSquare) {
  const SurfaceMesh mesh = cornell_box({50000});
  // Every triangle is half a cell: its two legs at the right-angle-ish corner have similar length.
  double shortest = 1e9, longest = 0;
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const double edge = (mesh.vertices.row(mesh.faces(f, (k + 1) % 3)) - mesh.vertices.row(mesh.faces(f, k))).norm();
      shortest = std::min(shortest, edge);
      longest = std::max(longest, edge);
    }
  }
  // Legs within ±~20% of the cell side h (rounding of cells per side), diagonals √2·h.
  EXPECT_LT(longest / shortest, 1.5 * std::sqrt(2.0));
}

TEST(LightGrid, RowMajorInZThenXInsetBelowTheCeiling) {
  const Box room = cornell_room();
  const LightGrid grid{12, 12, 0.05, 0.1};
  const std::vector<Eigen::Vector3d> lights = light_grid(room, grid);
  ASSERT_EQ(lights.size(), 144u);
  const double x0 = 0.1 * 0.556, x1 = 0.9 * 0.556, z0 = 0.1 * 0.5592, z1 = 0.9 * 0.5592;
  for (int iz = 0; iz < 12; ++iz) {
    for (int ix = 0; ix < 12; ++ix) {
      const Eigen::Vector3d& p = lights[static_cast<size_t>(iz * 12 + ix)];
      EXPECT_NEAR(p.x(), x0 + (x1 - x0) * ix / 11.0, 1e-12);
      EXPECT_NEAR(p.y(), 0.95 * 0.5488, 1e-12);
      EXPECT_NEAR(p.z(), z0 + (z1 - z0) * iz / 11.0, 1e-12);
    }
  }
  const std::vector<Eigen::Vector3d> one = light_grid(room, {1, 1, 0.5, 0.0});
  ASSERT_EQ(one.size(), 1u);
  EXPECT_TRUE(one[0].isApprox(Eigen::Vector3d(0.278, 0.2744, 0.2796), 1e-12));
  EXPECT_EQ(light_grid(room, {3, 2, 0.05, 0.1}).size(), 6u);
}

SurfaceMesh unit_square() {
  SurfaceMesh s;
  s.vertices.resize(4, 3);
  s.vertices << 0, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 1;
  s.normals.resize(4, 3);
  s.normals.rowwise() = Eigen::RowVector3f(0, 1, 0);
  s.albedo.resize(4, 3);
  s.albedo.rowwise() = Eigen::RowVector3f(0.5f, 0.5f, 0.5f);
  s.faces.resize(2, 3);
  s.faces << 0, 2, 1, 0, 3, 2;
  return s;
}

void expect_invalid(const Status& status, const std::vector<std::string>& parts) {
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
  for (const std::string& part : parts) EXPECT_NE(status.error().message.find(part), std::string::npos) << status.error().message;
}

TEST(CheckSurface, NamesTheFieldRowAndValue) {
  EXPECT_TRUE(check_surface(unit_square(), "s").ok());
  {
    SurfaceMesh s = unit_square();
    s.normals.conservativeResize(3, 3);
    expect_invalid(check_surface(s, "s"), {"s.normals", "3"});
  }
  {
    SurfaceMesh s = unit_square();
    s.albedo.conservativeResize(5, 3);
    expect_invalid(check_surface(s, "s"), {"s.albedo", "5"});
  }
  {
    SurfaceMesh s = unit_square();
    s.faces(1, 2) = 7;
    expect_invalid(check_surface(s, "s"), {"s.faces row 1", "7"});
  }
  {
    SurfaceMesh s = unit_square();
    s.faces(0, 0) = -1;
    expect_invalid(check_surface(s, "s"), {"s.faces row 0", "-1"});
  }
  {
    SurfaceMesh s = unit_square();
    s.vertices(2, 1) = std::nanf("");
    expect_invalid(check_surface(s, "s"), {"s.vertices row 2", "nan"});
  }
  {
    SurfaceMesh s = unit_square();
    s.normals.row(3) << 0, 0.5f, 0;
    expect_invalid(check_surface(s, "s"), {"s.normals row 3", "0.5"});
  }
  {
    SurfaceMesh s = unit_square();
    s.normals(1, 0) = std::numeric_limits<float>::infinity();
    expect_invalid(check_surface(s, "s"), {"s.normals row 1", "inf"});
  }
  {
    SurfaceMesh s = unit_square();
    s.albedo(2, 1) = 1.0f;
    expect_invalid(check_surface(s, "s"), {"s.albedo row 2", "1"});
  }
  {
    SurfaceMesh s = unit_square();
    s.albedo(0, 2) = -0.25f;
    expect_invalid(check_surface(s, "s"), {"s.albedo row 0", "-0.25"});
  }
}

}  // namespace
}  // namespace animspace::illumination
