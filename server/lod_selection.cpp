#include "server/lod_selection.h"

#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

#include "core/lod/selection.h"
#include "core/model/model_info.h"
#include "server/status_mapping.h"

namespace animspace::server {
namespace {

// A float as the client sent it ("-1", "0.5", "nan", "inf"), not std::to_string's "-1.000000".
std::string shown(float value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.9g", static_cast<double>(value));
  return text;
}

grpc::Status bad_view_field(const char* member, const char* expected, const std::string& got) {
  return invalid_argument(std::string("pixel_tolerance.") + member + ": expected " + expected + ", got " + got);
}

// The view is checked here, against the proto's own field names, before eq. 7.2 sees it: the core
// refuses the same values but names them as its LodView does.
grpc::Status check_view(const v1::PixelTolerance& view) {
  if (!std::isfinite(view.tolerance_px()) || view.tolerance_px() <= 0) {
    return bad_view_field("tolerance_px", "a finite value > 0", shown(view.tolerance_px()));
  }
  if (view.viewport_width_px() == 0) return bad_view_field("viewport_width_px", "a value > 0", "0");
  if (!std::isfinite(view.horizontal_fov_rad()) || view.horizontal_fov_rad() <= 0 ||
      static_cast<double>(view.horizontal_fov_rad()) >= std::numbers::pi) {
    return bad_view_field("horizontal_fov_rad", "a value in (0, π)", shown(view.horizontal_fov_rad()));
  }
  if (!std::isfinite(view.distance()) || view.distance() <= 0) {
    return bad_view_field("distance", "a finite value > 0", shown(view.distance()));
  }
  return grpc::Status::OK;
}

// A core refusal about a member of a request message, with the message's field name in front.
grpc::Status in_field(const char* field, const Error& error) {
  return to_grpc_status(Error{error.code, std::string(field) + "." + error.message});
}

}  // namespace

grpc::Status find_lod_levels(const LoadedModel& model, const lod::LodLevels** out) {
  if (!model.animation_space || !model.lod_levels) {
    return {grpc::StatusCode::FAILED_PRECONDITION,
            "model '" + model.name + "' version " + std::to_string(model.version) + " is of kind " +
                model::kind_name(model.info.kind) +
                " and has no skeleton: levels of detail are cut from an animation-space model (Merry 2007 §7.3)"};
  }
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
      const v1::PixelTolerance& view = request.pixel_tolerance();
      if (grpc::Status s = check_view(view); !s.ok()) return s;
      lod::ViewAtDistance eq72;
      eq72.tolerance_pixels = view.tolerance_px();
      eq72.viewport_width_pixels = view.viewport_width_px();
      eq72.horizontal_fov_radians = view.horizontal_fov_rad();
      eq72.distance = view.distance();
      auto chosen = lod::level_for_view(*levels, eq72, model.bounding_sphere.radius);
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
