#include "core/lod/levels.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numbers>
#include <string>

#include "core/common/format.h"
#include "core/lod/influence_simplification.h"

namespace animspace::lod {

namespace as = animation_space;

namespace {

// Where each vertex went: a collapse u → v sends u to v; a vertex's representative is the live
// vertex at the end of that chain (union–find with path compression).
class CollapseForest {
 public:
  explicit CollapseForest(int vertices) : parent_(static_cast<size_t>(vertices)) {
    for (int32_t v = 0; v < vertices; ++v) parent_[static_cast<size_t>(v)] = v;
  }

  void record(const Simplification& step) {
    if (step.kind == SimplificationKind::kEdgeCollapse) parent_[static_cast<size_t>(step.vertex)] = step.target;
  }

  // For each input vertex in `vertices`, the position in `live_ids` (a level's input ids) of its
  // representative.
  std::vector<int32_t> positions_of(const std::vector<int32_t>& vertices, const std::vector<int32_t>& live_ids) {
    std::vector<int32_t> compact(parent_.size(), -1);
    for (size_t k = 0; k < live_ids.size(); ++k) compact[static_cast<size_t>(live_ids[k])] = static_cast<int32_t>(k);
    std::vector<int32_t> out(vertices.size());
    for (size_t k = 0; k < vertices.size(); ++k) {
      out[k] = compact[static_cast<size_t>(representative(vertices[k]))];
      assert(out[k] >= 0);
    }
    return out;
  }

 private:
  int32_t representative(int32_t v) {
    int32_t root = v;
    while (parent_[static_cast<size_t>(root)] != root) root = parent_[static_cast<size_t>(root)];
    while (parent_[static_cast<size_t>(v)] != root) {
      const int32_t next = parent_[static_cast<size_t>(v)];
      parent_[static_cast<size_t>(v)] = root;
      v = next;
    }
    return root;
  }

  std::vector<int32_t> parent_;
};

LodLevel cut_level(const MeshState& state, const as::Skeleton& skeleton, double error, int64_t steps) {
  LodLevel level;
  level.model = state.to_model(skeleton, &level.vertex_ids, &level.face_ids);
  level.epsilon = error;
  level.step_count = steps;
  return level;
}

}  // namespace

LodLevels make_levels(const ProgressiveMesh& mesh, int max_levels) {
  assert(max_levels >= 1);
  LodLevels lods;
  MeshState state = mesh.state_after(0);
  CollapseForest forest(mesh.input_vertex_count);
  lods.levels.push_back(cut_level(state, mesh.skeleton, 0, 0));
  double error = 0;
  int budget = state.live_influence_count() / 2;
  for (size_t k = 0; k < mesh.steps.size() && lods.count() < max_levels; ++k) {
    const Simplification& step = mesh.steps[k];
    state.apply(step);
    error = std::max(error, step.cost);
    forest.record(step);
    const bool last = k + 1 == mesh.steps.size();
    if (state.live_influence_count() <= budget ||
        (last && lods.levels.back().step_count < static_cast<int64_t>(k + 1))) {
      lods.levels.push_back(cut_level(state, mesh.skeleton, error, static_cast<int64_t>(k + 1)));
      LodLevel& finer = lods.levels[lods.levels.size() - 2];
      finer.coarser_vertex = forest.positions_of(finer.vertex_ids, lods.levels.back().vertex_ids);
      budget = state.live_influence_count() / 2;
    }
  }
  return lods;
}

as::AnimationSpaceModel simplify_to_vertex_count(const ProgressiveMesh& mesh, int vertex_count,
                                                 std::vector<int32_t>* vertex_ids, double* error,
                                                 std::vector<int32_t>* representative) {
  MeshState state = mesh.state_after(0);
  CollapseForest forest(mesh.input_vertex_count);
  double worst = 0;
  for (size_t k = 0; k < mesh.steps.size() && state.live_vertex_count() > vertex_count; ++k) {
    const Simplification& step = mesh.steps[k];
    state.apply(step);
    worst = std::max(worst, step.cost);
    forest.record(step);
  }
  if (error) *error = worst;
  std::vector<int32_t> ids;
  as::AnimationSpaceModel model = state.to_model(mesh.skeleton, &ids);
  if (representative) {
    std::vector<int32_t> every(static_cast<size_t>(mesh.input_vertex_count));
    for (int32_t v = 0; v < mesh.input_vertex_count; ++v) every[static_cast<size_t>(v)] = v;
    *representative = forest.positions_of(every, ids);
  }
  if (vertex_ids) *vertex_ids = std::move(ids);
  return model;
}

Result<std::vector<LevelFit>> fit_levels(LodLevels& lods, const Eigen::MatrixXd& P, const LevelFitOptions& options) {
  std::vector<LevelFit> fits;
  if (lods.count() == 0) return fits;
  const as::AnimationSpaceModel& input = lods.levels[0].model;
  LevelFit exact;
  exact.influences_before = exact.influences = input.influences.influence_count();
  fits.push_back(exact);
  // Where every input vertex is at level l: follow coarser_vertex down from level 0.
  std::vector<int32_t> at(static_cast<size_t>(input.vertex_count()));
  for (int32_t v = 0; v < input.vertex_count(); ++v) at[static_cast<size_t>(v)] = v;
  double epsilon = 0;
  InfluenceSimplifier simplifier(P);  // its operators serve every level
  auto normalised = normalise_input(input, P);
  if (!normalised) return normalised.error();
  for (int l = 1; l < lods.count(); ++l) {
    const LodLevel& finer = lods.levels[static_cast<size_t>(l) - 1];
    for (int32_t& v : at) v = finer.coarser_vertex[static_cast<size_t>(v)];
    LodLevel& level = lods.levels[static_cast<size_t>(l)];
    Result<LevelFit> fit = fit_level(*normalised, at, level.model, options, &simplifier);
    if (!fit.ok()) return fit.error();
    epsilon = std::max(epsilon, fit->bound);
    level.epsilon = epsilon;
    fits.push_back(*fit);
  }
  return fits;
}

SimplifyOptions progressive_mesh_options(const LevelBuildOptions& options) {
  SimplifyOptions simplify;
  simplify.atlas = options.atlas;
  simplify.influence_simplification = options.influence_simplification && !options.placement;
  simplify.max_normal_deviation_degrees = options.max_normal_deviation_degrees;
  simplify.progress = options.progress;
  return simplify;
}

LevelFitOptions level_fit_options(const LevelBuildOptions& options) {
  LevelFitOptions fit;
  fit.influence_exchange = options.influence_simplification ? options.influence_exchange : -1;
  return fit;
}

Result<BuiltLevels> build_levels(const as::AnimationSpaceModel& model, const as::AnimationSpaceMetrics& metrics,
                                 const LevelBuildOptions& options) {
  auto pm = build_progressive_mesh(model, metrics, progressive_mesh_options(options));
  if (!pm) return pm.error();
  BuiltLevels built;
  built.steps = pm->steps.size();
  built.lods = make_levels(*pm, options.max_levels);
  if (options.placement) {
    auto fits = fit_levels(built.lods, metrics.P, level_fit_options(options));
    if (!fits) return fits.error();
    built.fits = std::move(*fits);
  }
  if (options.atlas) {
    // Placement moved positions only: a corner keeps its input vertex's UV (chart_atlas.h).
    auto charts = ChartUvs::build(*options.atlas, model.faces);
    if (!charts) return charts.error();
    for (LodLevel& level : built.lods.levels) {
      auto uvs = level_corner_uvs(*charts, level.model.faces, level.face_ids, level.vertex_ids,
                                  static_cast<int32_t>(model.faces.rows()));
      if (!uvs) return uvs.error();
      level.corner_uvs = std::move(*uvs);
    }
  }
  return built;
}

Geomorph geomorph(const LodLevels& lods, int level) {
  assert(level >= 0 && level + 1 < lods.count());
  const LodLevel& fine = lods.levels[static_cast<size_t>(level)];
  const LodLevel& coarse = lods.levels[static_cast<size_t>(level) + 1];
  const as::InfluenceSets& fi = fine.model.influences;
  const as::InfluenceSets& ci = coarse.model.influences;
  Geomorph morph;
  std::vector<Eigen::Vector4d> position;
  std::vector<Eigen::Vector4d> delta;
  for (int v = 0; v < fine.model.vertex_count(); ++v) {
    const int c = fine.coarser_vertex[static_cast<size_t>(v)];
    int i = fi.begin(v);
    int j = ci.begin(c);
    // Merge the two sorted bone lists: p^l and p^{l+1} on their union.
    while (i < fi.end(v) || j < ci.end(c)) {
      const int32_t bi = i < fi.end(v) ? fi.bones[static_cast<size_t>(i)] : INT32_MAX;
      const int32_t bj = j < ci.end(c) ? ci.bones[static_cast<size_t>(j)] : INT32_MAX;
      const int32_t bone = std::min(bi, bj);
      const Eigen::Vector4d p = bi == bone ? Eigen::Vector4d(fine.model.positions.col(i++)) : Eigen::Vector4d::Zero();
      const Eigen::Vector4d q = bj == bone ? Eigen::Vector4d(coarse.model.positions.col(j++)) : Eigen::Vector4d::Zero();
      morph.aligned.bones.push_back(bone);
      position.push_back(p);
      delta.push_back(q - p);
    }
    morph.aligned.offsets.push_back(static_cast<int32_t>(morph.aligned.bones.size()));
  }
  morph.position.resize(4, static_cast<Eigen::Index>(position.size()));
  morph.delta.resize(4, static_cast<Eigen::Index>(delta.size()));
  for (size_t k = 0; k < position.size(); ++k) {
    morph.position.col(static_cast<Eigen::Index>(k)) = position[k];
    morph.delta.col(static_cast<Eigen::Index>(k)) = delta[k];
  }
  return morph;
}

as::AnimationSpaceModel geomorphed_model(const LodLevels& lods, int level, double t) {
  assert(t >= 0 && t <= 1);
  const LodLevel& fine = lods.levels[static_cast<size_t>(level)];
  const Geomorph morph = geomorph(lods, level);
  as::AnimationSpaceModel model;
  model.skeleton = fine.model.skeleton;
  model.faces = fine.model.faces;
  model.influences = morph.aligned;
  model.positions = morph.position + t * morph.delta;  // eq. 7.1
  return model;
}

Status validate(const PixelTolerance& view) {
  const auto bad = [](const char* field, const std::string& expected, double got) {
    return Status(make_error(ErrorCode::kInvalidArgument,
                             std::string(field) + ": expected " + expected + ", got " + format_number(got)));
  };
  if (!std::isfinite(view.tolerance_px) || view.tolerance_px <= 0) {
    return bad("tolerance_px", "a finite value > 0", view.tolerance_px);
  }
  if (!std::isfinite(view.viewport_width_px) || view.viewport_width_px <= 0) {
    return bad("viewport_width_px", "a finite value > 0", view.viewport_width_px);
  }
  if (!std::isfinite(view.horizontal_fov_rad) || view.horizontal_fov_rad <= 0 ||
      view.horizontal_fov_rad >= std::numbers::pi) {
    return bad("horizontal_fov_rad", "a value in (0, π)", view.horizontal_fov_rad);
  }
  if (!std::isfinite(view.distance) || view.distance <= 0) {
    return bad("distance", "a finite value > 0", view.distance);
  }
  return Status::Ok();
}

Result<double> tolerated_error(const PixelTolerance& view, double bounding_radius) {
  ANIMSPACE_RETURN_IF_ERROR(validate(view));
  const double depth = view.distance - bounding_radius;
  if (!(depth > 0)) return 0.0;
  const double theta = view.horizontal_fov_rad / 2;
  return 2 * view.tolerance_px * depth * std::sin(theta) / view.viewport_width_px;  // eq. 7.2
}

double select_level(const LodLevels& lods, double tolerated) {
  assert(lods.count() >= 1);
  const int last = lods.count() - 1;
  int k = 0;
  for (int l = 1; l <= last; ++l) {
    if (lods.levels[static_cast<size_t>(l)].epsilon <= tolerated) k = l;
  }
  if (k == last) return last;
  const double lo = lods.levels[static_cast<size_t>(k)].epsilon;
  const double hi = lods.levels[static_cast<size_t>(k) + 1].epsilon;
  return k + (tolerated - lo) / (hi - lo);
}

}  // namespace animspace::lod
