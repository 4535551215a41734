#include "core/lod/selection.h"

#include <cmath>

#include "core/animspace/animspace_io.h"
#include "core/animspace/tangents.h"
#include "core/geometry/bounding_sphere.h"

namespace animspace::lod {

Result<LevelChoice> level_for_view(const LodLevels& lods, const PixelTolerance& view, double bounding_radius) {
  auto tolerated = tolerated_error(view, bounding_radius);
  if (!tolerated) return tolerated.error();
  return LevelChoice{static_cast<int>(std::floor(select_level(lods, *tolerated))), *tolerated};
}

Result<int> level_for_vertex_budget(const LodLevels& lods, int64_t max_vertices) {
  for (int l = 0; l < lods.count(); ++l) {
    if (lods.levels[static_cast<size_t>(l)].model.vertex_count() <= max_vertices) return l;
  }
  std::string message = "max_vertices: expected at least " +
                        std::to_string(lods.levels.back().model.vertex_count()) +
                        " (the coarsest level's vertex count), got " + std::to_string(max_vertices);
  // Issue #55: a model with level 0 alone is the usual reason; say how to give it levels.
  if (lods.count() == 1) {
    message += "; the model has only level 0 (full detail): build coarser levels into a new version with "
               "`animspace build-lod MODEL.anim -o REPOSITORY --model NAME`";
  }
  return make_error(ErrorCode::kOutOfRange, message);
}

Result<geometry::BoundingSphere> model_bounding_sphere(const container::ModelContainer& in,
                                                              const animation_space::AnimationSpaceModel& model,
                                                              const std::string& source) {
  auto stored = animation_space::load_metrics(in, model.bone_count(), source);
  if (stored) return stored->bounding_sphere;
  if (stored.error().code != ErrorCode::kNotFound) return stored.error();
  return geometry::bounding_sphere(animation_space::rest_positions(model));
}

}  // namespace animspace::lod
