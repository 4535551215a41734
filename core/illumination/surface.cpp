// The Cornell box tessellated into illumination sample points, and the checks of a surface.
//
// Data: "Cornell Box Data", Cornell Program of Computer Graphics,
// https://www.graphics.cornell.edu/online/box/data.html (millimetres, y up; the room spans
// x 0…556, y 0…548.8, z 0…559.2 and is open at z = 0, where the camera stands).
#include "core/illumination/surface.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <string>

#include <Eigen/Geometry>


namespace animspace::illumination {

namespace {

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

// The shortest text that reads back as the same float (format_number would print the float's
// exact double value: 0.001f as 0.0010000000474974513).
std::string format_float(float value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

std::string row_text(const PointMatrix& m, Eigen::Index r) {
  return "(" + format_float(m(r, 0)) + ", " + format_float(m(r, 1)) + ", " + format_float(m(r, 2)) + ")";
}

// ---- Cornell box data --------------------------------------------------------------------------

constexpr double kMillimetre = 1e-3;
constexpr double kRoomWidth = 556.0;   // x
constexpr double kRoomHeight = 548.8;  // y
constexpr double kRoomDepth = 559.2;   // z

const Eigen::Vector3d kWhite(0.73, 0.71, 0.68);
const Eigen::Vector3d kRed(0.63, 0.065, 0.05);
const Eigen::Vector3d kGreen(0.14, 0.45, 0.091);

// Which side of a face is lit: the room's walls face its interior, the blocks' faces face away
// from the block.
enum class Facing { kTowardsRoomCentre, kAwayFromShortBlock, kAwayFromTallBlock };

struct CornellQuad {
  std::array<std::array<double, 3>, 4> corners_mm;  // consecutive around the quad, as published
  Facing facing;
  const Eigen::Vector3d* albedo;
};

// The published quads (the ceiling light's cut-out is not modelled: the ceiling is one quad).
const std::array<CornellQuad, 15> kCornellQuads = {{
    // Floor.
    {{{{552.8, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 559.2}, {549.6, 0.0, 559.2}}}, Facing::kTowardsRoomCentre, &kWhite},
    // Ceiling.
    {{{{556.0, 548.8, 0.0}, {556.0, 548.8, 559.2}, {0.0, 548.8, 559.2}, {0.0, 548.8, 0.0}}},
     Facing::kTowardsRoomCentre, &kWhite},
    // Back wall.
    {{{{549.6, 0.0, 559.2}, {0.0, 0.0, 559.2}, {0.0, 548.8, 559.2}, {556.0, 548.8, 559.2}}},
     Facing::kTowardsRoomCentre, &kWhite},
    // Right wall (green, x = 0; on the camera's right).
    {{{{0.0, 0.0, 559.2}, {0.0, 0.0, 0.0}, {0.0, 548.8, 0.0}, {0.0, 548.8, 559.2}}}, Facing::kTowardsRoomCentre, &kGreen},
    // Left wall (red, x ≈ 556).
    {{{{552.8, 0.0, 0.0}, {549.6, 0.0, 559.2}, {556.0, 548.8, 559.2}, {556.0, 548.8, 0.0}}},
     Facing::kTowardsRoomCentre, &kRed},
    // Short block: top, then four sides.
    {{{{130.0, 165.0, 65.0}, {82.0, 165.0, 225.0}, {240.0, 165.0, 272.0}, {290.0, 165.0, 114.0}}},
     Facing::kAwayFromShortBlock, &kWhite},
    {{{{290.0, 0.0, 114.0}, {290.0, 165.0, 114.0}, {240.0, 165.0, 272.0}, {240.0, 0.0, 272.0}}},
     Facing::kAwayFromShortBlock, &kWhite},
    {{{{130.0, 0.0, 65.0}, {130.0, 165.0, 65.0}, {290.0, 165.0, 114.0}, {290.0, 0.0, 114.0}}},
     Facing::kAwayFromShortBlock, &kWhite},
    {{{{82.0, 0.0, 225.0}, {82.0, 165.0, 225.0}, {130.0, 165.0, 65.0}, {130.0, 0.0, 65.0}}},
     Facing::kAwayFromShortBlock, &kWhite},
    {{{{240.0, 0.0, 272.0}, {240.0, 165.0, 272.0}, {82.0, 165.0, 225.0}, {82.0, 0.0, 225.0}}},
     Facing::kAwayFromShortBlock, &kWhite},
    // Tall block: top, then four sides.
    {{{{423.0, 330.0, 247.0}, {265.0, 330.0, 296.0}, {314.0, 330.0, 456.0}, {472.0, 330.0, 406.0}}},
     Facing::kAwayFromTallBlock, &kWhite},
    {{{{423.0, 0.0, 247.0}, {423.0, 330.0, 247.0}, {472.0, 330.0, 406.0}, {472.0, 0.0, 406.0}}},
     Facing::kAwayFromTallBlock, &kWhite},
    {{{{472.0, 0.0, 406.0}, {472.0, 330.0, 406.0}, {314.0, 330.0, 456.0}, {314.0, 0.0, 456.0}}},
     Facing::kAwayFromTallBlock, &kWhite},
    {{{{314.0, 0.0, 456.0}, {314.0, 330.0, 456.0}, {265.0, 330.0, 296.0}, {265.0, 0.0, 296.0}}},
     Facing::kAwayFromTallBlock, &kWhite},
    {{{{265.0, 0.0, 296.0}, {265.0, 330.0, 296.0}, {423.0, 330.0, 247.0}, {423.0, 0.0, 247.0}}},
     Facing::kAwayFromTallBlock, &kWhite},
}};

// A quad in metres with its lit-side unit normal and its grid's sides.
struct Quad {
  std::array<Eigen::Vector3d, 4> p;  // p0 → p1 is the grid's u direction, p0 → p3 its v direction
  Eigen::Vector3d normal;
  double length_u = 0;  // mean of the two u edges
  double length_v = 0;
  const Eigen::Vector3d* albedo = nullptr;

  double area() const { return 0.5 * (p[2] - p[0]).cross(p[3] - p[1]).norm(); }
};

// The centre of a block: the mean of its top's corners, at half its height.
Eigen::Vector3d block_centre(const CornellQuad& top) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& c : top.corners_mm) centre += Eigen::Vector3d(c[0], c[1], c[2]);
  centre /= 4.0;
  centre.y() *= 0.5;
  return centre * kMillimetre;
}

std::vector<Quad> cornell_quads() {
  const Eigen::Vector3d room_centre = 0.5 * kMillimetre * Eigen::Vector3d(kRoomWidth, kRoomHeight, kRoomDepth);
  const Eigen::Vector3d short_centre = block_centre(kCornellQuads[5]);
  const Eigen::Vector3d tall_centre = block_centre(kCornellQuads[10]);
  std::vector<Quad> quads;
  for (const CornellQuad& data : kCornellQuads) {
    Quad q;
    for (int c = 0; c < 4; ++c) {
      const auto& mm = data.corners_mm[static_cast<size_t>(c)];
      q.p[static_cast<size_t>(c)] = kMillimetre * Eigen::Vector3d(mm[0], mm[1], mm[2]);
    }
    // The cross product of the diagonals is the normal of a planar quad and the best-fit
    // direction of a slightly twisted one.
    q.normal = (q.p[2] - q.p[0]).cross(q.p[3] - q.p[1]).normalized();
    const Eigen::Vector3d centroid = 0.25 * (q.p[0] + q.p[1] + q.p[2] + q.p[3]);
    Eigen::Vector3d towards_lit = Eigen::Vector3d::Zero();
    switch (data.facing) {
      case Facing::kTowardsRoomCentre: towards_lit = room_centre - centroid; break;
      case Facing::kAwayFromShortBlock: towards_lit = centroid - short_centre; break;
      case Facing::kAwayFromTallBlock: towards_lit = centroid - tall_centre; break;
    }
    if (q.normal.dot(towards_lit) < 0) q.normal = -q.normal;
    q.length_u = 0.5 * ((q.p[1] - q.p[0]).norm() + (q.p[2] - q.p[3]).norm());
    q.length_v = 0.5 * ((q.p[3] - q.p[0]).norm() + (q.p[2] - q.p[1]).norm());
    q.albedo = data.albedo;
    quads.push_back(q);
  }
  return quads;
}

struct GridSize {
  int cells_u = 1;
  int cells_v = 1;
  int64_t vertices() const { return int64_t{cells_u + 1} * (cells_v + 1); }
};

GridSize grid_size(const Quad& q, double cell) {
  // Capped so that absurd targets cannot overflow the vertex count.
  auto cells = [cell](double length) { return static_cast<int>(std::clamp(std::round(length / cell), 1.0, 1e6)); };
  return {cells(q.length_u), cells(q.length_v)};
}

int64_t vertex_count(const std::vector<Quad>& quads, double cell) {
  int64_t count = 0;
  for (const Quad& q : quads) count += grid_size(q, cell).vertices();
  return count;
}

// The cell side whose total vertex count is nearest to `target`. The count falls (in steps) as
// the cell grows, so bisect for the step that crosses the target, starting from the interior
// estimate area / h² = target.
double cell_side_for(const std::vector<Quad>& quads, int64_t target) {
  double area = 0;
  for (const Quad& q : quads) area += q.area();
  double small = std::sqrt(area / static_cast<double>(std::max<int64_t>(target, 1))) / 4.0;  // count ≥ target
  double large = 0;                                                                              // count < target
  for (const Quad& q : quads) large = std::max({large, 4.0 * q.length_u, 4.0 * q.length_v});
  if (vertex_count(quads, large) >= target) return large;  // the minimum tessellation already reaches it
  for (int i = 0; i < 100 && vertex_count(quads, small) < target; ++i) small /= 2;
  for (int i = 0; i < 60; ++i) {
    const double middle = 0.5 * (small + large);
    (vertex_count(quads, middle) >= target ? small : large) = middle;
  }
  const int64_t above = vertex_count(quads, small) - target;
  const int64_t below = target - vertex_count(quads, large);
  return above <= below ? small : large;
}

// Appends q's grid: bilinear in the corners, one normal and one albedo for the whole face, two
// triangles per cell wound counter-clockwise seen from the lit side.
void append_grid(const Quad& q, GridSize size, SurfaceMesh& mesh, Eigen::Index& vertex, Eigen::Index& face) {
  const Eigen::Index first = vertex;
  const int nu = size.cells_u + 1;
  for (int j = 0; j <= size.cells_v; ++j) {
    const double t = static_cast<double>(j) / size.cells_v;
    for (int i = 0; i <= size.cells_u; ++i) {
      const double s = static_cast<double>(i) / size.cells_u;
      const Eigen::Vector3d x =
          (1 - s) * (1 - t) * q.p[0] + s * (1 - t) * q.p[1] + s * t * q.p[2] + (1 - s) * t * q.p[3];
      mesh.vertices.row(vertex) = x.cast<float>().transpose();
      mesh.normals.row(vertex) = q.normal.cast<float>().transpose();
      mesh.albedo.row(vertex) = q.albedo->cast<float>().transpose();
      ++vertex;
    }
  }
  // u × v points to the lit side or away from it, the same for every cell of a convex quad.
  const bool u_cross_v_lit = (q.p[1] - q.p[0]).cross(q.p[3] - q.p[0]).dot(q.normal) > 0;
  for (int j = 0; j < size.cells_v; ++j) {
    for (int i = 0; i < size.cells_u; ++i) {
      const auto a = static_cast<int32_t>(first + j * nu + i);
      const int32_t b = a + 1;
      const int32_t c = a + 1 + nu;
      const int32_t d = a + nu;
      if (u_cross_v_lit) {
        mesh.faces.row(face++) << a, b, c;
        mesh.faces.row(face++) << a, c, d;
      } else {
        mesh.faces.row(face++) << a, c, b;
        mesh.faces.row(face++) << a, d, c;
      }
    }
  }
}

}  // namespace

Status check_surface(const SurfaceMesh& surface, const std::string& name) {
  const Eigen::Index n = surface.vertices.rows();
  if (surface.normals.rows() != n) {
    return invalid(name + ".normals has " + std::to_string(surface.normals.rows()) + " rows; " + name +
                   ".vertices has " + std::to_string(n));
  }
  if (surface.albedo.rows() != n) {
    return invalid(name + ".albedo has " + std::to_string(surface.albedo.rows()) + " rows; " + name +
                   ".vertices has " + std::to_string(n));
  }
  for (Eigen::Index v = 0; v < n; ++v) {
    if (!surface.vertices.row(v).allFinite()) {
      return invalid(name + ".vertices row " + std::to_string(v) + " is not finite: " + row_text(surface.vertices, v));
    }
    if (!surface.normals.row(v).allFinite()) {
      return invalid(name + ".normals row " + std::to_string(v) + " is not finite: " + row_text(surface.normals, v));
    }
    const auto length = static_cast<float>(surface.normals.row(v).cast<double>().norm());
    if (std::abs(length - 1.0) > 1e-3) {
      return invalid(name + ".normals row " + std::to_string(v) + " " + row_text(surface.normals, v) + " has length " +
                     format_float(length) + ", not 1 (±1e-3)");
    }
    for (int k = 0; k < 3; ++k) {
      const float rho = surface.albedo(v, k);
      if (!(rho >= 0.0f && rho < 1.0f)) {  // also rejects NaN
        return invalid(name + ".albedo row " + std::to_string(v) + " " + row_text(surface.albedo, v) +
                       ": each channel must be in [0, 1), channel " + std::to_string(k) + " is " + format_float(rho));
      }
    }
  }
  for (Eigen::Index f = 0; f < surface.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t index = surface.faces(f, k);
      if (index < 0 || index >= n) {
        return invalid(name + ".faces row " + std::to_string(f) + " refers to vertex " + std::to_string(index) +
                       "; there are " + std::to_string(n) + " vertices");
      }
    }
  }
  return Status::Ok();
}

SurfaceMesh cornell_box(const CornellBoxOptions& options) {
  const std::vector<Quad> quads = cornell_quads();
  const double cell = cell_side_for(quads, options.target_points);
  int64_t vertices = 0;
  int64_t triangles = 0;
  for (const Quad& q : quads) {
    const GridSize size = grid_size(q, cell);
    vertices += size.vertices();
    triangles += int64_t{2} * size.cells_u * size.cells_v;
  }
  SurfaceMesh mesh;
  mesh.vertices.resize(vertices, 3);
  mesh.normals.resize(vertices, 3);
  mesh.albedo.resize(vertices, 3);
  mesh.faces.resize(triangles, 3);
  Eigen::Index vertex = 0;
  Eigen::Index face = 0;
  for (const Quad& q : quads) append_grid(q, grid_size(q, cell), mesh, vertex, face);
  assert(vertex == vertices && face == triangles);
  return mesh;
}

Box cornell_room() {
  return {Eigen::Vector3d::Zero(), kMillimetre * Eigen::Vector3d(kRoomWidth, kRoomHeight, kRoomDepth)};
}

std::vector<Eigen::Vector3d> light_grid(const Box& room, const LightGrid& grid) {
  assert(grid.nx >= 1 && grid.nz >= 1);
  const Eigen::Vector3d size = room.max - room.min;
  const double y = room.max.y() - grid.drop * size.y();
  // Evenly spaced from one inset line to the other, ends included; a single light sits midway.
  auto coordinate = [](double low, double high, int index, int count) {
    return count == 1 ? 0.5 * (low + high) : low + (high - low) * index / (count - 1);
  };
  const double x0 = room.min.x() + grid.inset * size.x();
  const double x1 = room.max.x() - grid.inset * size.x();
  const double z0 = room.min.z() + grid.inset * size.z();
  const double z1 = room.max.z() - grid.inset * size.z();
  std::vector<Eigen::Vector3d> positions;
  positions.reserve(static_cast<size_t>(grid.nx) * static_cast<size_t>(grid.nz));
  for (int iz = 0; iz < grid.nz; ++iz) {
    for (int ix = 0; ix < grid.nx; ++ix) {
      positions.emplace_back(coordinate(x0, x1, ix, grid.nx), y, coordinate(z0, z1, iz, grid.nz));
    }
  }
  return positions;
}

}  // namespace animspace::illumination
