// Storing a texture atlas beside its model in the model container (docs/FORMATS.md, "atlas").
//
// Sections (names in core/container/sections.h): atlas.chart_ids (#F × 1 i32: the chart of each
// face, numbered densely from 0) and atlas.uvs (#F × 6 f64: u, v of corners 0, 1, 2 of each face,
// in [0, 1]²; float64 so that the stored map is exactly the one-to-one map that was checked).
// Metadata: atlas.format_version (1), atlas.charts (the chart count), atlas.metric ("poses": P of
// the model's pose distribution, or "rest_pose"). A model without the sections has no atlas and
// loads as before.
#pragma once

#include <optional>
#include <string>

#include "core/atlas/atlas.h"
#include "core/common/result.h"
#include "core/container/model_container.h"

namespace animspace::atlas {

inline constexpr int kAtlasFormatVersion = 1;

// Writes the sections and metadata (`metric` is written as atlas.metric).
void store_atlas(const Atlas& atlas, const std::string& metric, container::ModelContainer& out);

// The stored atlas of a model with `face_count` faces, or nullopt when it has none.
// Errors: kFailedPrecondition for a format version newer than this reader's; kInvalidArgument
// naming `source` and the section for a wrong shape, chart ids out of range or not dense, UVs not
// finite or outside [0, 1].
Result<std::optional<Atlas>> load_atlas(const container::ModelContainer& in, long face_count, const std::string& source);

}  // namespace animspace::atlas
