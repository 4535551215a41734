#include "core/atlas/atlas_io.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/container/sections.h"

namespace animspace::atlas {

namespace sections = container::sections;

void store_atlas(const Atlas& atlas, const std::string& metric, container::ModelContainer& out) {
  const auto F = static_cast<Eigen::Index>(atlas.chart_of_face.size());
  container::Int32Matrix ids(F, 1);
  container::Float64Matrix uvs(F, 6);
  for (Eigen::Index f = 0; f < F; ++f) {
    ids(f, 0) = atlas.chart_of_face[static_cast<size_t>(f)];
    for (int k = 0; k < 3; ++k) {
      uvs(f, 2 * k) = atlas.uvs(3 * f + k, 0);
      uvs(f, 2 * k + 1) = atlas.uvs(3 * f + k, 1);
    }
  }
  out.set_matrix(sections::kAtlasChartIds, ids);
  out.set_matrix(sections::kAtlasUvs, uvs);
  out.metadata()["atlas.format_version"] = std::to_string(kAtlasFormatVersion);
  out.metadata()["atlas.charts"] = std::to_string(atlas.chart_count);
  out.metadata()["atlas.metric"] = metric;
}

Result<std::optional<Atlas>> load_atlas(const container::ModelContainer& in, long face_count, const std::string& source) {
  if (!in.has_section(sections::kAtlasChartIds) && !in.has_section(sections::kAtlasUvs)) {
    return std::optional<Atlas>();
  }
  const auto bad = [&](const std::string& what) {
    return make_error(ErrorCode::kInvalidArgument, source + ": " + what);
  };
  const std::string version = in.metadata_value("atlas.format_version", "1");
  if (version != "1") {
    return make_error(ErrorCode::kFailedPrecondition,
                      source + ": atlas.format_version " + version + " is newer than this reader's (1)");
  }
  auto ids = in.int_matrix(sections::kAtlasChartIds);
  if (!ids) return ids.error();
  auto uvs = in.double_matrix(sections::kAtlasUvs);
  if (!uvs) return uvs.error();
  const std::string expected_ids = std::to_string(face_count) + "×1";
  if (ids->rows() != face_count || ids->cols() != 1) {
    return container::section_shape_error(source, sections::kAtlasChartIds, expected_ids, ids->rows(), ids->cols());
  }
  if (uvs->rows() != face_count || uvs->cols() != 6) {
    return container::section_shape_error(source, sections::kAtlasUvs, std::to_string(face_count) + "×6", uvs->rows(),
                                          uvs->cols());
  }
  Atlas atlas;
  atlas.chart_of_face.assign(ids->data(), ids->data() + face_count);
  int32_t largest = -1;
  for (long f = 0; f < face_count; ++f) {
    const int32_t c = atlas.chart_of_face[static_cast<size_t>(f)];
    if (c < 0) return bad(std::string(sections::kAtlasChartIds) + ": face " + std::to_string(f) + " has chart " + std::to_string(c));
    largest = std::max(largest, c);
  }
  std::vector<char> used(static_cast<size_t>(largest + 1), 0);
  for (int32_t c : atlas.chart_of_face) used[static_cast<size_t>(c)] = 1;
  for (size_t c = 0; c < used.size(); ++c) {
    if (!used[c]) return bad(std::string(sections::kAtlasChartIds) + ": chart " + std::to_string(c) + " has no face (ids must be dense)");
  }
  atlas.chart_count = largest + 1;
  atlas.uvs.resize(3 * face_count, 2);
  for (long f = 0; f < face_count; ++f) {
    for (int k = 0; k < 6; ++k) {
      const double x = (*uvs)(f, k);
      if (!std::isfinite(x) || x < 0 || x > 1) {
        return bad(std::string(sections::kAtlasUvs) + ": face " + std::to_string(f) + " has a UV outside [0, 1]");
      }
      atlas.uvs(3 * f + k / 2, k % 2) = x;
    }
  }
  return std::optional<Atlas>(std::move(atlas));
}

}  // namespace animspace::atlas
