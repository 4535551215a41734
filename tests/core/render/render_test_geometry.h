// Reference geometry for the render tests: meshes whose shape is known in closed form, and a
// pinhole camera written out independently of core/render/camera.cpp (from the field of view and
// aspect alone), so that tests compare the renderer against analytic answers rather than
// against its own arithmetic.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/common/types.h"
#include "core/render/scene.h"

namespace animspace::render::testing {

// A unit icosphere: the icosahedron with each triangle split in four `subdivisions` times and
// the new vertices pushed onto the sphere. 20·4^k triangles, counter-clockwise from outside.
inline TriangleMesh icosphere(int subdivisions) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Eigen::Vector3d> points = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (Eigen::Vector3d& p : points) p.normalize();
  std::vector<Eigen::Vector3i> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int k = 0; k < subdivisions; ++k) {
    std::map<std::pair<int, int>, int> midpoints;
    const auto midpoint = [&](int a, int b) {
      const std::pair<int, int> key(std::min(a, b), std::max(a, b));
      const auto it = midpoints.find(key);
      if (it != midpoints.end()) return it->second;
      points.push_back((points[static_cast<size_t>(a)] + points[static_cast<size_t>(b)]).normalized());
      const int index = static_cast<int>(points.size()) - 1;
      midpoints.emplace(key, index);
      return index;
    };
    std::vector<Eigen::Vector3i> finer;
    for (const Eigen::Vector3i& f : faces) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      finer.insert(finer.end(), {{f[0], ab, ca}, {f[1], bc, ab}, {f[2], ca, bc}, {ab, bc, ca}});
    }
    faces = std::move(finer);
  }
  TriangleMesh mesh;
  mesh.V.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (size_t i = 0; i < points.size(); ++i) mesh.V.row(static_cast<Eigen::Index>(i)) = points[i].cast<float>().transpose();
  mesh.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) mesh.F.row(static_cast<Eigen::Index>(i)) = faces[i].transpose();
  return mesh;
}

// The cube [−1, 1]³: 8 corners (bit k of the index is the sign of coordinate k), 12 triangles.
inline TriangleMesh cube() {
  TriangleMesh mesh;
  mesh.V.resize(8, 3);
  for (int i = 0; i < 8; ++i) {
    mesh.V.row(i) << ((i & 1) ? 1.0f : -1.0f), ((i & 2) ? 1.0f : -1.0f), ((i & 4) ? 1.0f : -1.0f);
  }
  mesh.F.resize(12, 3);
  mesh.F << 0, 2, 3, 0, 3, 1,  // z = −1
      4, 5, 7, 4, 7, 6,        // z = +1
      0, 1, 5, 0, 5, 4,        // y = −1
      2, 6, 7, 2, 7, 3,        // y = +1
      0, 4, 6, 0, 6, 2,        // x = −1
      1, 3, 7, 1, 7, 5;        // x = +1
  return mesh;
}

// A pinhole camera from first principles: looking from `eye` at `target`, the image plane at
// distance 1 spans ±tan(fov/2) vertically and ±aspect·tan(fov/2) horizontally; pixel (i, j)
// covers [i, i+1] × [j, j+1] with rows counted from the top.
struct Pinhole {
  Eigen::Vector3d eye, forward, right, up;
  double tan_half = 0;
  int width = 0, height = 0;

  Pinhole(const Eigen::Vector3d& eye_, const Eigen::Vector3d& target, const Eigen::Vector3d& up_hint, double fov,
          int width_, int height_)
      : eye(eye_), tan_half(std::tan(fov / 2)), width(width_), height(height_) {
    forward = (target - eye).normalized();
    right = forward.cross(up_hint).normalized();
    up = right.cross(forward);
  }
  double aspect() const { return static_cast<double>(width) / height; }

  // Image coordinates (pixels, continuous) of a point in front of the camera.
  Eigen::Vector2d project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - eye;
    const double depth = d.dot(forward);
    const double x = d.dot(right) / (depth * tan_half * aspect());  // −1 … 1 across the image
    const double y = d.dot(up) / (depth * tan_half);
    return {(x + 1) / 2 * width, (1 - y) / 2 * height};
  }

  // Unit direction of the ray through the image point (u, v) in pixels.
  Eigen::Vector3d ray(double u, double v) const {
    const double x = 2 * u / width - 1;
    const double y = 1 - 2 * v / height;
    return (forward + x * tan_half * aspect() * right + y * tan_half * up).normalized();
  }
  // The ray through the centre of pixel (i, j).
  Eigen::Vector3d pixel_ray(int i, int j) const { return ray(i + 0.5, j + 0.5); }
};

// Distance along the unit ray (origin, direction) to its first hit with the sphere, if any.
inline std::optional<double> hit_sphere(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                        const Eigen::Vector3d& centre, double radius) {
  const Eigen::Vector3d oc = origin - centre;
  const double b = oc.dot(direction);
  const double discriminant = b * b - (oc.squaredNorm() - radius * radius);
  if (discriminant < 0) return std::nullopt;
  const double t = -b - std::sqrt(discriminant);
  if (t <= 0) return std::nullopt;
  return t;
}

// A camera in one expression.
inline Camera make_camera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up,
                          double fov) {
  Camera camera;
  camera.eye = eye;
  camera.target = target;
  camera.up = up;
  camera.vertical_fov_rad = fov;
  return camera;
}

}  // namespace animspace::render::testing
