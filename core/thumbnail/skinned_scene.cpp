#include "core/thumbnail/skinned_scene.h"

#include <cassert>
#include <cmath>
#include <cstddef>

#include "core/geometry/bounding_sphere.h"
#include "core/lod/selection.h"
#include "core/render/camera.h"

namespace animspace::thumbnail {

Result<int> pose_skinned(const animation_space::AnimationSpaceModel& model, const lod::LodLevels* lods,
                         const animation_space::TransformList& globals, double tolerance_px, render::Scene& scene) {
  assert(scene.width >= 1 && scene.height >= 1);
  assert(std::isfinite(tolerance_px) && tolerance_px >= 0);
  const animation_space::AnimationSpaceModel* drawn = &model;
  int level = 0;
  animation_space::evaluate(model, globals, scene.points);
  if (tolerance_px > 0 && lods != nullptr && lods->count() > 1) {
    const double aspect = static_cast<double>(scene.width) / scene.height;
    if (!scene.camera) {
      auto framed = render::frame_bounding_box(scene.points, aspect);
      if (!framed) return framed.error();
      scene.camera = *framed;
    }
    // Eq. 7.2 needs the depth of the nearest point of a sphere around the posed mesh.
    const geometry::BoundingSphere sphere = geometry::bounding_sphere(scene.points);
    lod::PixelTolerance view;
    view.tolerance_px = tolerance_px;
    view.viewport_width_px = scene.width;
    view.horizontal_fov_rad = render::horizontal_fov(*scene.camera, aspect);
    view.distance = (scene.camera->eye - sphere.centre).norm();
    auto choice = lod::level_for_view(*lods, view, sphere.radius);
    if (!choice) return choice.error();
    level = choice->level;
    if (level > 0) {
      drawn = &lods->levels[static_cast<size_t>(level)].model;
      animation_space::evaluate(*drawn, globals, scene.points);
    }
  }
  scene.faces = drawn->faces;
  if (drawn->has_tangents()) animation_space::evaluate_normals(*drawn, globals, scene.normals);
  return level;
}

}  // namespace animspace::thumbnail
