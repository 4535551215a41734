// Internal to core/mesh_io: what the OBJ, PLY and OFF parsers share to assemble a TriangleMesh.
#pragma once

#include <cassert>
#include <cstdint>
#include <span>
#include <vector>

#include "core/common/types.h"

namespace animspace::mesh_io {

// Vertices and polygons in file order.
class MeshBuilder {
 public:
  int vertex_count() const { return static_cast<int>(points_.size() / 3); }
  void add_vertex(float x, float y, float z) { points_.insert(points_.end(), {x, y, z}); }
  // Fan-triangulates a polygon of zero-based indices: (a b c d …) → (a b c) (a c d) …
  void add_polygon(std::span<const int32_t> polygon) {
    assert(polygon.size() >= 3);
    for (size_t k = 1; k + 1 < polygon.size(); ++k) {
      triangles_.insert(triangles_.end(), {polygon[0], polygon[k], polygon[k + 1]});
    }
  }
  TriangleMesh build() const {
    TriangleMesh mesh;
    mesh.V = Eigen::Map<const PointMatrix>(points_.data(), static_cast<Eigen::Index>(points_.size() / 3), 3);
    mesh.F = Eigen::Map<const FaceMatrix>(triangles_.data(), static_cast<Eigen::Index>(triangles_.size() / 3), 3);
    return mesh;
  }

 private:
  std::vector<float> points_;       // x y z per vertex
  std::vector<int32_t> triangles_;  // a b c per triangle
};

}  // namespace animspace::mesh_io
