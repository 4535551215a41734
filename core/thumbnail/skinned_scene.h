// An animation-space model posed for a thumbnail, at the coarsest level of detail the thumbnail's
// screen tolerance allows (Merry 2007 §7.3): eq. 7.2 with the thumbnail's own camera and width,
// against a sphere around the mesh as posed.
#pragma once

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/lod/levels.h"
#include "core/render/scene.h"

namespace animspace::thumbnail {

// Poses `model` at `globals` (G_j, one per bone) into scene.points, scene.faces and, when the
// drawn model has tangents, scene.normals (§3.5); returns the level drawn (0: `model` itself).
//
// With tolerance_px > 0 (pixels, finite — asserted) and `lods` (may be null) holding more than
// one level, the level is ⌊l⌋ of lod::level_for_view for a viewer of scene.width pixels with the
// scene's camera — framed around the full-detail posed mesh and stored in the scene when it has
// none (render::frame_bounding_box) — at the distance from the eye to the centre of the posed
// mesh's bounding sphere (geometry::bounding_sphere), and that level is posed instead. Otherwise
// full detail, and the camera is left as it is.
//
// scene.width and scene.height must be ≥ 1 (asserted). Errors: kInvalidArgument from
// frame_bounding_box (points not all finite) or level_for_view (the view: e.g. a camera whose
// field of view makes the horizontal one reach π).
Result<int> pose_skinned(const animation_space::AnimationSpaceModel& model, const lod::LodLevels* lods,
                         const animation_space::TransformList& globals, double tolerance_px, render::Scene& scene);

}  // namespace animspace::thumbnail
