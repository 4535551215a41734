#include "core/lod/chart_atlas.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace animspace::lod {

namespace {

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, "atlas: " + std::move(message)); }

}  // namespace

Result<ChartUvs> ChartUvs::build(const ChartAtlas& atlas, const FaceMatrix& faces) {
  const Eigen::Index F = faces.rows();
  if (static_cast<Eigen::Index>(atlas.chart_of_face.size()) != F) {
    return invalid("chart_of_face: expected " + std::to_string(F) + " charts (one per face), got " +
                   std::to_string(atlas.chart_of_face.size()));
  }
  if (atlas.uvs.rows() != 3 * F) {
    return invalid("uvs: expected " + std::to_string(3 * F) + " rows (3 per face), got " +
                   std::to_string(atlas.uvs.rows()));
  }
  ChartUvs out;
  out.chart_of_face_ = atlas.chart_of_face;
  int32_t charts = 0;
  for (Eigen::Index f = 0; f < F; ++f) {
    const int32_t c = atlas.chart_of_face[static_cast<size_t>(f)];
    if (c < 0) return invalid("chart_of_face row " + std::to_string(f) + ": expected a chart ≥ 0, got " + std::to_string(c));
    charts = std::max(charts, c + 1);
  }
  out.orientation_.assign(static_cast<size_t>(charts), 0);
  std::vector<Eigen::Index> oriented_by(static_cast<size_t>(charts), -1);
  out.uv_.reserve(static_cast<size_t>(3 * F));
  for (Eigen::Index f = 0; f < F; ++f) {
    const int32_t c = atlas.chart_of_face[static_cast<size_t>(f)];
    Eigen::Vector2d corner[3];
    for (int k = 0; k < 3; ++k) {
      corner[k] = atlas.uvs.row(3 * f + k).transpose();
      if (!corner[k].allFinite()) {
        return invalid("uvs row " + std::to_string(3 * f + k) + " (face " + std::to_string(f) + " corner " +
                       std::to_string(k) + "): expected finite values");
      }
      const int32_t v = faces(f, k);
      const auto [at, inserted] = out.uv_.emplace(key(v, c), corner[k]);
      if (!inserted && at->second != corner[k]) {
        return invalid("vertex " + std::to_string(v) + " has two UVs in chart " + std::to_string(c) +
                       " (face " + std::to_string(f) + " corner " + std::to_string(k) +
                       "); a chart must have one UV per vertex");
      }
    }
    const double area = signed_uv_area(corner[0], corner[1], corner[2]);
    if (area == 0) continue;  // a degenerate face orients nothing; collapses never create one
    const int sign = area > 0 ? 1 : -1;
    int& orientation = out.orientation_[static_cast<size_t>(c)];
    if (orientation == 0) {
      orientation = sign;
      oriented_by[static_cast<size_t>(c)] = f;
    } else if (orientation != sign) {
      return invalid("chart " + std::to_string(c) + " has faces of both orientations in UV (faces " +
                     std::to_string(oriented_by[static_cast<size_t>(c)]) + " and " + std::to_string(f) +
                     "); a chart's map must be one-to-one");
    }
  }
  for (int& orientation : out.orientation_) {
    if (orientation == 0) orientation = 1;  // a chart of degenerate faces only (or no faces)
  }
  return out;
}

const Eigen::Vector2d* ChartUvs::find(int32_t v, int32_t c) const {
  const auto at = uv_.find(key(v, c));
  return at == uv_.end() ? nullptr : &at->second;
}

Result<CornerUvs> level_corner_uvs(const ChartUvs& charts, const FaceMatrix& level_faces,
                                   const std::vector<int32_t>& face_ids, const std::vector<int32_t>& vertex_ids,
                                   int32_t input_face_count) {
  if (static_cast<Eigen::Index>(face_ids.size()) != level_faces.rows()) {
    return make_error(ErrorCode::kInvalidArgument, "face_ids: expected " + std::to_string(level_faces.rows()) +
                                                       " (one per face of the level), got " +
                                                       std::to_string(face_ids.size()));
  }
  CornerUvs out(3 * level_faces.rows(), 2);
  for (Eigen::Index f = 0; f < level_faces.rows(); ++f) {
    const int32_t input_face = face_ids[static_cast<size_t>(f)];
    if (input_face < 0 || input_face >= input_face_count) {
      return make_error(ErrorCode::kInvalidArgument, "face_ids row " + std::to_string(f) + ": expected a face in [0, " +
                                                         std::to_string(input_face_count) + "), got " +
                                                         std::to_string(input_face));
    }
    const int32_t c = charts.chart_of(input_face);
    for (int k = 0; k < 3; ++k) {
      const int32_t w = level_faces(f, k);
      if (w < 0 || w >= static_cast<int32_t>(vertex_ids.size())) {
        return make_error(ErrorCode::kInvalidArgument, "faces row " + std::to_string(f) + ": vertex " +
                                                           std::to_string(w) + " out of range");
      }
      const int32_t v = vertex_ids[static_cast<size_t>(w)];
      const Eigen::Vector2d* uv = charts.find(v, c);
      if (uv == nullptr) {
        return make_error(ErrorCode::kInvalidArgument,
                          "face " + std::to_string(f) + " (input face " + std::to_string(input_face) + ", chart " +
                              std::to_string(c) + ") corner " + std::to_string(k) + ": input vertex " +
                              std::to_string(v) +
                              " has no UV in that chart; the level was not simplified within the atlas's charts");
      }
      out.row(3 * f + k) = uv->transpose();
    }
  }
  return out;
}

}  // namespace animspace::lod
