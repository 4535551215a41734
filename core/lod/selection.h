// Choosing one discrete level of detail for a viewer that cannot geomorph: a render-farm node
// pulling a mesh, a file written for a DCC tool, a thumbnail (Merry 2007 §7.3).
//
// §7.3 picks a real-valued level and geomorphs between its two neighbours (levels.h). A consumer
// of one discrete mesh takes the finer of the two, ⌊l⌋, so that the error it draws never exceeds
// what the viewer tolerates.
#pragma once

#include <cstdint>
#include <string>

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/lod/levels.h"

namespace animspace::lod {

struct LevelChoice {
  int level = 0;
  // ε of eq. 7.2 for this view (0 when the camera is inside the bounding sphere).
  double tolerated_error = 0;
};

// ⌊l⌋ for the ε that tolerated_error gives `view` (levels.h, eq. 7.2); a camera inside or on the
// sphere of `bounding_radius` sees full detail. Errors: validate(view)'s.
Result<LevelChoice> level_for_view(const LodLevels& lods, const PixelTolerance& view, double bounding_radius);

// The finest level with at most `max_vertices` vertices.
// Errors: kOutOfRange when even the coarsest level is larger, giving its vertex count.
Result<int> level_for_vertex_budget(const LodLevels& lods, int64_t max_vertices);

// The sphere eq. 7.2 measures depth to: the pose-independent sphere stored with the model's
// metrics (§7.2) when it has them, otherwise the sphere around its rest pose (centre of the
// bounding box, radius to the farthest vertex) — exact for the rest pose only.
// Errors: those of reading the stored metrics, other than their absence.
Result<geometry::BoundingSphere> model_bounding_sphere(const container::ModelContainer& in,
                                                              const animation_space::AnimationSpaceModel& model,
                                                              const std::string& source);

}  // namespace animspace::lod
