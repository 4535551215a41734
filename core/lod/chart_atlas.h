// A texture atlas as level of detail sees it: the chart of every input face and the UV of every
// face corner, so that simplification keeps the chart borders and every level carries UVs
// (issue #37; Merry 2007 §5.1, §5.3).
//
// Merry 2007 §5.1: level-of-detail schemes "are unable to simplify features that cross chart
// boundaries" — the borders are where simplification must stop; §5.3 (Fig. 5.5): "simplification
// should not allow parts of parameter space to appear or disappear from the model", so a border
// vertex may only be removed along its border. What simplify.h enforces with an atlas:
//   - a vertex inside a chart collapses as before, but no face of its new fan may flip or become
//     degenerate in UV (the chart's map stays one-to-one face by face);
//   - a vertex on the border of exactly two charts (two border edges, not on the mesh boundary)
//     collapses only along one of its two border edges, onto the next vertex of the same border;
//   - a vertex where three or more charts meet, or where a border reaches the mesh boundary,
//     never moves;
// so no collapse joins two charts and every border of a level runs along original border edges
// through original border vertices. (The thesis further asks the border to be straight in UV at a
// removed vertex; the atlas here leaves borders free in UV (atlas/atlas.h), so a border collapse
// moves the chart's UV outline by the skipped vertex: coverage is kept by chart, not exactly.)
//
// UVs of a level: each face keeps its input face number, hence its chart; a corner's UV is the UV
// its vertex — an input vertex, since collapses are half-edge collapses (§6.2.1) — has in that
// chart. The collapse rules guarantee that vertex touches the chart in the input (by induction: a
// vertex collapses only onto a neighbour across a face of the same chart, or along a border onto
// a vertex of both charts). Placement (level_fit.h) moves positions, never UVs: a placed vertex
// keeps the texture coordinate of the input vertex it is, which interpolating along one collapsed
// edge would not improve (a level vertex stands for many collapses, and its placed position fits
// all of them), and which keeps every border vertex exactly on its chart's UV border.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"
#include "core/common/result.h"

namespace animspace::lod {

// 3·#F × 2: row 3f + k is (u, v) of corner k of face f (atlas::CornerUvs' layout).
using CornerUvs = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

struct ChartAtlas {
  std::vector<int32_t> chart_of_face;  // #F of the input, ≥ 0
  CornerUvs uvs;                       // 3·#F × 2, finite
};

// One UV per (vertex, chart) and each chart's orientation in UV, checked once.
class ChartUvs {
 public:
  // Errors: kInvalidArgument naming "atlas" and what is wrong: sizes against `faces`, a negative
  // chart, a UV that is not finite, a vertex with two different UVs in one chart (a chart must be
  // cut only along its border), or a chart whose faces have both orientations in UV.
  static Result<ChartUvs> build(const ChartAtlas& atlas, const FaceMatrix& faces);

  int32_t chart_of(int32_t face) const { return chart_of_face_[static_cast<size_t>(face)]; }
  // UV of vertex v in chart c, or null when v is a corner of no face of c.
  const Eigen::Vector2d* find(int32_t v, int32_t c) const;
  // +1 or −1: the sign of every face of chart c's signed UV area, corners in face order.
  int orientation(int32_t c) const { return orientation_[static_cast<size_t>(c)]; }

 private:
  static uint64_t key(int32_t v, int32_t c) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(v)) << 32) | static_cast<uint32_t>(c);
  }
  std::vector<int32_t> chart_of_face_;
  std::vector<int> orientation_;
  std::unordered_map<uint64_t, Eigen::Vector2d> uv_;
};

// Twice the signed area of the UV triangle (a, b, c).
inline double signed_uv_area(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  const Eigen::Vector2d e1 = b - a;
  const Eigen::Vector2d e2 = c - a;
  return e1.x() * e2.y() - e1.y() * e2.x();
}

// The corner UVs of a level (3·#F_l × 2): face f of the level is input face face_ids[f], in that
// face's chart; its corner k is level vertex level_faces(f, k), input vertex vertex_ids[·].
// Errors: kInvalidArgument when a corner's vertex has no UV in its face's chart (a level not built
// under the atlas's borders), or ids out of range.
Result<CornerUvs> level_corner_uvs(const ChartUvs& charts, const FaceMatrix& level_faces,
                                   const std::vector<int32_t>& face_ids, const std::vector<int32_t>& vertex_ids,
                                   int32_t input_face_count);

}  // namespace animspace::lod
