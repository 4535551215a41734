// Turning a request's choice of level of detail into a level (Merry 2007 §7.3): by index, by a
// view (eq. 7.2, through lod::level_for_view) or by a vertex budget. The one place the server does
// this, so SkinningService's lod_level and LodService's selection refuse in the same words.
#pragma once

#include <cstdint>
#include <string_view>

#include <grpcpp/support/status.h>

#include "animspace/v1/lod.pb.h"
#include "core/lod/levels.h"
#include "server/model_registry.h"

namespace animspace::server {

// The levels of `model` (level 0 = the model itself): OK and `out` set, or FAILED_PRECONDITION
// naming the model's kind when it has no skeleton — a mesh sequence, or a PMSC model without an
// animation-space posing engine (a PMSC model with one serves its engine's levels).
grpc::Status find_lod_levels(const LoadedModel& model, const lod::LodLevels** out);

// Level `level` of `model`: OK and `out` set; FAILED_PRECONDITION as find_lod_levels; or
// INVALID_ARGUMENT naming `field` with the valid range and the level count
// ("lod_level: expected 0..9 (model 'arm' has 10 levels), got 12").
grpc::Status find_lod_level(const LoadedModel& model, uint32_t level, std::string_view field,
                            const lod::LodLevel** out);

struct LodChoice {
  int level = 0;
  const lod::LodLevel* lod = nullptr;  // into the model's levels
  // ε of eq. 7.2 for the request's view, model units (pixel_tolerance; 0 otherwise).
  double tolerated_error = 0;
};

// GetLodRequest's `selection`: the level an explicit index names, the one lod::level_for_view
// chooses for pixel_tolerance (⌊l⌋ of eq. 7.2 against the model's bounding sphere), or the finest
// within budget (lod::level_for_vertex_budget). Refusals name the proto field: INVALID_ARGUMENT
// for no selection, a view field out of range or a level out of range; OUT_OF_RANGE for a budget
// below the coarsest level; FAILED_PRECONDITION for a model without levels.
grpc::Status select_lod_level(const LoadedModel& model, const v1::GetLodRequest& request, LodChoice* out);

}  // namespace animspace::server
