#include "core/lod/selection.h"

#include <cmath>

#include "core/animspace/animspace_io.h"
#include "core/animspace/tangents.h"

namespace animspace::lod {

Result<LevelChoice> level_for_view(const LodLevels& lods, const ViewAtDistance& view, double bounding_radius) {
  LodView eq72;
  eq72.tolerance_pixels = view.tolerance_pixels;
  eq72.viewport_width_pixels = view.viewport_width_pixels;
  eq72.horizontal_fov_radians = view.horizontal_fov_radians;
  // Validated through tolerated_error with a stand-in depth, so that a bad view is refused even
  // when the camera turns out to be inside the sphere.
  eq72.nearest_depth = 1;
  if (auto checked = tolerated_error(eq72); !checked) return checked.error();
  if (!std::isfinite(view.distance) || view.distance <= 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "distance: expected a finite value > 0, got " + std::to_string(view.distance));
  }
  const double depth = view.distance - bounding_radius;
  if (depth <= 0) return LevelChoice{};
  eq72.nearest_depth = depth;
  auto tolerated = tolerated_error(eq72);
  if (!tolerated) return tolerated.error();
  return LevelChoice{static_cast<int>(std::floor(select_level(lods, *tolerated))), *tolerated};
}

Result<int> level_for_vertex_budget(const LodLevels& lods, int64_t max_vertices) {
  for (int l = 0; l < lods.count(); ++l) {
    if (lods.levels[static_cast<size_t>(l)].model.vertex_count() <= max_vertices) return l;
  }
  return make_error(ErrorCode::kOutOfRange, "max_vertices: expected at least " +
                                                std::to_string(lods.levels.back().model.vertex_count()) +
                                                " (the coarsest level's vertex count), got " +
                                                std::to_string(max_vertices));
}

Result<animation_space::BoundingSphere> model_bounding_sphere(const container::ModelContainer& in,
                                                              const animation_space::AnimationSpaceModel& model,
                                                              const std::string& source) {
  auto stored = animation_space::load_metrics(in, model.bone_count(), source);
  if (stored) return stored->bounding_sphere;
  if (stored.error().code != ErrorCode::kNotFound) return stored.error();
  const Eigen::MatrixX3d rest = animation_space::rest_positions(model);
  animation_space::BoundingSphere sphere;
  if (rest.rows() == 0) return sphere;
  sphere.centre = (rest.colwise().minCoeff() + rest.colwise().maxCoeff()).transpose() / 2;
  sphere.radius = (rest.rowwise() - sphere.centre.transpose()).rowwise().norm().maxCoeff();
  return sphere;
}

}  // namespace animspace::lod
