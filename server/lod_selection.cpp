#include "server/lod_selection.h"

#include <cassert>
#include <string>

#include "core/lod/selection.h"
#include "server/convert.h"
#include "server/model_lookup.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

// A core refusal about a member of a request message, with the message's field name in front.
grpc::Status in_field(const char* field, const Error& error) {
  return to_grpc_status(Error{error.code, std::string(field) + "." + error.message});
}

}  // namespace

grpc::Status find_lod_levels(const LoadedModel& model, const lod::LodLevels** out) {
  if (grpc::Status s = require_skeleton(model, "levels of detail are cut from an animation-space model (Merry 2007 §7.3)");
      !s.ok()) {
    return s;
  }
  // The registry builds levels for every model with a skeleton (model::load_servable).
  assert(model.lod_levels);
  *out = model.lod_levels.get();
  return grpc::Status::OK;
}

grpc::Status find_lod_level(const LoadedModel& model, uint32_t level, std::string_view field,
                            const lod::LodLevel** out) {
  const lod::LodLevels* levels = nullptr;
  if (grpc::Status s = find_lod_levels(model, &levels); !s.ok()) return s;
  const int count = levels->count();
  if (level >= static_cast<uint32_t>(count)) {
    return invalid_argument(std::string(field) + ": expected 0.." + std::to_string(count - 1) + " (model '" +
                            model.name + "' has " + std::to_string(count) + " level" + (count == 1 ? "" : "s") +
                            "), got " + std::to_string(level));
  }
  *out = &levels->levels[level];
  return grpc::Status::OK;
}

grpc::Status select_lod_level(const LoadedModel& model, const v1::GetLodRequest& request, LodChoice* out) {
  const lod::LodLevels* levels = nullptr;
  if (grpc::Status s = find_lod_levels(model, &levels); !s.ok()) return s;
  LodChoice choice;
  switch (request.selection_case()) {
    case v1::GetLodRequest::kLevel:
      if (grpc::Status s = find_lod_level(model, request.level(), "level", &choice.lod); !s.ok()) return s;
      choice.level = static_cast<int>(request.level());
      break;
    case v1::GetLodRequest::kPixelTolerance: {
      // The core validates the view (lod::validate) under the proto's own field names.
      const lod::PixelTolerance view = from_proto(request.pixel_tolerance());
      auto chosen = lod::level_for_view(*levels, view, model.bounding_sphere.radius);
      if (!chosen) return in_field("pixel_tolerance", chosen.error());
      choice.level = chosen->level;
      choice.tolerated_error = chosen->tolerated_error;
      break;
    }
    case v1::GetLodRequest::kBudget: {
      auto chosen = lod::level_for_vertex_budget(*levels, request.budget().max_vertices());
      if (!chosen) return in_field("budget", chosen.error());
      choice.level = *chosen;
      break;
    }
    case v1::GetLodRequest::SELECTION_NOT_SET:
      return invalid_argument("selection: expected one of pixel_tolerance, budget or level, got none");
  }
  choice.lod = &levels->levels[static_cast<size_t>(choice.level)];
  *out = choice;
  return grpc::Status::OK;
}

}  // namespace animspace::server
