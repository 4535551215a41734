// Storing LOD levels beside their animation-space model in the model container.
//
// Sections (docs/FORMATS.md): lod.errors (L × 1 f64, ε^l; row 0 is 0 and stands for the model
// itself, stored by animspace_io), and for every level l ≥ 1 the model's own four influence
// sections under the prefix "lod.<l>." (influence_offsets, influence_bones, positions, tangents)
// plus lod.<l>.faces (F_l × 3 i32) and lod.<l>.vertex_ids (V_l × 1 i32: the level-0 vertex each
// vertex is). For every level l < L−1, lod.<l>.coarser_vertex (V_l × 1 i32) names the vertex
// of level l+1 that each vertex collapses into — what geomorphing needs (§7.3). Levels share
// the model's skeleton. Optional, per level l ≥ 1: lod.<l>.face_ids (F_l × 1 i32: the level-0
// face each face is, increasing) and, for levels built under a texture atlas (chart_atlas.h),
// lod.<l>.uvs (F_l × 6 f64: u, v of corners 0, 1, 2 of each face, in [0, 1]², the layout of
// atlas.uvs). Files without them load as before, their levels without face ids or UVs.
#pragma once

#include <string>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/lod/levels.h"

namespace animspace::lod {

namespace sections {
inline constexpr const char* kErrors = "lod.errors";
}

// Writes levels 1… and lod.errors; level 0 must be the model already stored (asserted: same
// vertex count). Sets metadata "lod_levels".
void store_levels(const LodLevels& lods, container::ModelContainer& out);

// Reads the levels of a stored model (`model` is its level 0, already loaded). A model without
// lod.errors has one level, itself.
// Errors: kInvalidArgument naming `source`, the section and expected vs actual for shapes, ε^l
// that are negative, not finite or decreasing, vertex ids that are not increasing level-0
// vertices, face ids that are not increasing level-0 faces, UVs not finite or outside [0, 1],
// coarser_vertex out of range, or a level that fails validate(model).
Result<LodLevels> load_levels(const container::ModelContainer& in, const animation_space::AnimationSpaceModel& model,
                              const std::string& source);

}  // namespace animspace::lod
