// Distance from points to a triangle surface, the one yardstick the LOD benchmark and tests use
// for every simplifier (ours and the rest-pose baselines alike): it knows nothing about how a
// mesh was simplified, only where its triangles are.
//
// The triangles are binned into a uniform grid over their bounding box (about as many cells as
// triangles); a query searches shells of cells outwards from the point's cell and stops once the
// nearest triangle found is closer than any unsearched shell can be. Exact point–triangle
// distance in double: the foot of the perpendicular when it falls inside the triangle (by its
// barycentric coordinates), otherwise the nearest of the one or two edges it falls beyond (the
// region classification of Eberly's algorithm, without its ill-conditioned 2×2 solve).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"

namespace animspace::lod {

using Points3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// Exact distance from q to the closed triangle (a, b, c); degenerate triangles (segments or
// points) are handled.
double point_triangle_distance(const Eigen::Vector3d& q, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const Eigen::Vector3d& c);

class SurfaceDistance {
 public:
  // `points` #V × 3, `faces` #F × 3 indices into them (asserted in range; #F ≥ 1).
  SurfaceDistance(const Points3d& points, const FaceMatrix& faces);

  // Unsigned distance from q to the nearest point of any triangle (NaN when q has a NaN
  // coordinate, +inf when it has an infinite one). Thread-safe (const, no caches).
  double distance(const Eigen::Vector3d& q) const;

 private:
  // One triangle, precomputed for the query: corner a, edges e0 = b − a, e1 = c − a, e2 = c − b
  // with their inverse squared lengths (0 for a zero-length edge), the unit normal and the dual
  // vectors that give the barycentric coordinates (s, t) of the projection of q as
  // ((q − a)·u, (q − a)·w), and the bounding box [lo, hi]. `slack` bounds the rounding of the
  // plane distance (q − a)·normal relative to |q − a| (large for slivers). Degenerate triangles
  // (segments, points) use the edges only.
  struct Triangle {
    // What the pruning tests read first, then the rest.
    Eigen::Vector3d lo, hi;  // bounding box
    Eigen::Vector3d a, normal;
    double slack = 0;
    bool degenerate = false;
    Eigen::Vector3d u, w;
    Eigen::Vector3d e0, e1, e2;
    double inv0 = 0, inv1 = 0, inv2 = 0;
  };
  static Triangle make_triangle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);
  static double squared_distance(const Triangle& triangle, const Eigen::Vector3d& q);
  friend double point_triangle_distance(const Eigen::Vector3d&, const Eigen::Vector3d&, const Eigen::Vector3d&,
                                        const Eigen::Vector3d&);

  // Grid layout: cell (i, j, k) spans origin_ + cell_size_ · [i, i+1) × [j, j+1) × [k, k+1); its
  // triangles are cell_faces_[cell_offsets_[cell] .. cell_offsets_[cell + 1]) (compressed rows,
  // cell = (k · dims_.y() + j) · dims_.x() + i). upper_ is the bounding box's far corner,
  // grid_end_ the far end of the last cells in cell units (≥ dims_, reaching upper_).
  std::vector<Triangle> triangles_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d upper_ = Eigen::Vector3d::Zero();
  double cell_size_ = 1;
  Eigen::Vector3d grid_end_ = Eigen::Vector3d::Ones();
  Eigen::Vector3i dims_ = Eigen::Vector3i::Ones();
  std::vector<int32_t> cell_offsets_;
  std::vector<int32_t> cell_faces_;
};

// Root-mean-square and maximum of the distances from each row of `queries` to the surface.
struct DistanceSummary {
  double rms = 0;
  double max = 0;
  double sum_of_squares = 0;
  long count = 0;
};
DistanceSummary distances_to_surface(const Points3d& queries, const SurfaceDistance& surface);

}  // namespace animspace::lod
