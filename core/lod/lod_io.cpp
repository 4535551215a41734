#include "core/lod/lod_io.h"

#include <cassert>
#include <cmath>

#include "core/animspace/animspace_io.h"

namespace animspace::lod {

namespace as = animation_space;
using container::Float64Matrix;

namespace {

std::string prefix(int level) { return "lod." + std::to_string(level) + "."; }

Error invalid(const std::string& source, const std::string& message) {
  return make_error(ErrorCode::kInvalidArgument, source + ": " + message);
}

Result<std::vector<int32_t>> read_column(const container::ModelContainer& in, const std::string& name,
                                         Eigen::Index rows, const std::string& source) {
  auto m = in.int_matrix(name, 1);
  if (!m) return make_error(m.error().code, source + ": " + m.error().message);
  if (m->rows() != rows) {
    return invalid(source, "section '" + name + "' should have " + std::to_string(rows) + " rows, got " +
                               std::to_string(m->rows()));
  }
  return std::vector<int32_t>(m->data(), m->data() + m->size());
}

// lod.<l>.face_ids and lod.<l>.uvs, when stored.
Status load_level_faces(const container::ModelContainer& in, int l, Eigen::Index input_faces,
                        const std::string& source, LodLevel& level) {
  const Eigen::Index F = level.model.faces.rows();
  if (in.has_section(prefix(l) + "face_ids")) {
    auto ids = read_column(in, prefix(l) + "face_ids", F, source);
    if (!ids) return ids.error();
    for (size_t k = 0; k < ids->size(); ++k) {
      const int32_t id = (*ids)[k];
      const int32_t previous = k == 0 ? -1 : (*ids)[k - 1];
      if (id <= previous || id >= input_faces) {
        return invalid(source, "section '" + prefix(l) + "face_ids' row " + std::to_string(k) +
                                   ": expected a level-0 face in (" + std::to_string(previous) + ", " +
                                   std::to_string(input_faces) + "), got " + std::to_string(id));
      }
    }
    level.face_ids = std::move(*ids);
  }
  if (in.has_section(prefix(l) + "uvs")) {
    const std::string name = prefix(l) + "uvs";
    auto uvs = in.double_matrix(name, 6);
    if (!uvs) return make_error(uvs.error().code, source + ": " + uvs.error().message);
    if (uvs->rows() != F) {
      return invalid(source, "section '" + name + "' should have " + std::to_string(F) + " rows (one per face of level " +
                                 std::to_string(l) + "), got " + std::to_string(uvs->rows()));
    }
    for (Eigen::Index r = 0; r < F; ++r) {
      for (Eigen::Index c = 0; c < 6; ++c) {
        const double x = (*uvs)(r, c);
        if (!(x >= 0 && x <= 1)) {  // also NaN
          return invalid(source, "section '" + name + "' row " + std::to_string(r) + " column " + std::to_string(c) +
                                     ": expected a UV in [0, 1], got " + std::to_string(x));
        }
      }
    }
    level.corner_uvs = Eigen::Map<const CornerUvs>(uvs->data(), 3 * F, 2);
  }
  return Status::Ok();
}

}  // namespace

void store_levels(const LodLevels& lods, container::ModelContainer& out) {
  assert(lods.count() >= 1);
  Float64Matrix errors(lods.count(), 1);
  for (int l = 0; l < lods.count(); ++l) {
    const LodLevel& level = lods.levels[static_cast<size_t>(l)];
    errors(l, 0) = level.epsilon;
    if (l > 0) {
      as::store_influences(level.model, prefix(l), out);
      out.set_faces(prefix(l) + "faces", level.model.faces);
      out.set_matrix(prefix(l) + "vertex_ids", container::as_column(level.vertex_ids));
      if (!level.face_ids.empty()) out.set_matrix(prefix(l) + "face_ids", container::as_column(level.face_ids));
      if (level.corner_uvs.rows() > 0) {
        assert(level.corner_uvs.rows() == 3 * level.model.faces.rows());
        // 3F × 2 row-major is F × 6 row-major: the same doubles in the same order.
        out.set_matrix(prefix(l) + "uvs", Float64Matrix(Eigen::Map<const Float64Matrix>(
                                              level.corner_uvs.data(), level.model.faces.rows(), 6)));
      }
    }
    if (l + 1 < lods.count()) out.set_matrix(prefix(l) + "coarser_vertex", container::as_column(level.coarser_vertex));
  }
  out.set_matrix(sections::kErrors, errors);
  out.metadata()["lod_levels"] = std::to_string(lods.count());
}

Result<LodLevels> load_levels(const container::ModelContainer& in, const as::AnimationSpaceModel& model,
                              const std::string& source) {
  LodLevels lods;
  LodLevel base;
  base.model = model;
  base.vertex_ids.resize(static_cast<size_t>(model.vertex_count()));
  for (int v = 0; v < model.vertex_count(); ++v) base.vertex_ids[static_cast<size_t>(v)] = v;
  base.face_ids.resize(static_cast<size_t>(model.faces.rows()));
  for (int32_t f = 0; f < static_cast<int32_t>(model.faces.rows()); ++f) base.face_ids[static_cast<size_t>(f)] = f;
  lods.levels.push_back(std::move(base));
  if (!in.has_section(sections::kErrors)) return lods;

  auto errors = in.double_matrix(sections::kErrors, 1);
  if (!errors) return make_error(errors.error().code, source + ": " + errors.error().message);
  const Eigen::Index L = errors->rows();
  if (L < 1 || (*errors)(0, 0) != 0) {
    return invalid(source, "section 'lod.errors' should start with 0 (level 0 is the model itself)");
  }
  for (Eigen::Index l = 1; l < L; ++l) {
    const double e = (*errors)(l, 0);
    if (!std::isfinite(e) || e < (*errors)(l - 1, 0)) {
      return invalid(source, "section 'lod.errors' row " + std::to_string(l) + ": expected a finite ε^l ≥ " +
                                 std::to_string((*errors)(l - 1, 0)) + " (the previous level's), got " +
                                 std::to_string(e));
    }
  }
  for (int l = 1; l < L; ++l) {
    LodLevel level;
    level.epsilon = (*errors)(l, 0);
    level.model.skeleton = model.skeleton;
    ANIMSPACE_RETURN_IF_ERROR(as::load_influences(in, prefix(l), source, level.model));
    auto faces = in.faces(prefix(l) + "faces");
    if (!faces) return make_error(faces.error().code, source + ": " + faces.error().message);
    level.model.faces = std::move(*faces);
    const Status valid = as::validate(level.model);
    if (!valid.ok()) return invalid(source, "level " + std::to_string(l) + ": " + valid.error().message);
    auto ids = read_column(in, prefix(l) + "vertex_ids", level.model.vertex_count(), source);
    if (!ids) return ids.error();
    level.vertex_ids = std::move(*ids);
    for (size_t k = 0; k < level.vertex_ids.size(); ++k) {
      const int32_t id = level.vertex_ids[k];
      const int32_t previous = k == 0 ? -1 : level.vertex_ids[k - 1];
      if (id <= previous || id >= model.vertex_count()) {
        return invalid(source, "section '" + prefix(l) + "vertex_ids' row " + std::to_string(k) +
                                   ": expected a level-0 vertex in (" + std::to_string(previous) + ", " +
                                   std::to_string(model.vertex_count()) + "), got " + std::to_string(id));
      }
    }
    ANIMSPACE_RETURN_IF_ERROR(load_level_faces(in, l, model.faces.rows(), source, level));
    lods.levels.push_back(std::move(level));
  }
  for (int l = 0; l + 1 < L; ++l) {
    LodLevel& level = lods.levels[static_cast<size_t>(l)];
    auto coarser = read_column(in, prefix(l) + "coarser_vertex", level.model.vertex_count(), source);
    if (!coarser) return coarser.error();
    const int limit = lods.levels[static_cast<size_t>(l) + 1].model.vertex_count();
    for (size_t k = 0; k < coarser->size(); ++k) {
      if ((*coarser)[k] < 0 || (*coarser)[k] >= limit) {
        return invalid(source, "section '" + prefix(l) + "coarser_vertex' row " + std::to_string(k) +
                                   ": expected a vertex of level " + std::to_string(l + 1) + " in [0, " +
                                   std::to_string(limit) + "), got " + std::to_string((*coarser)[k]));
      }
    }
    level.coarser_vertex = std::move(*coarser);
  }
  return lods;
}

}  // namespace animspace::lod
