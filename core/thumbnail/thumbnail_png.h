// A drawn thumbnail as PNG bytes: the heat map's legend first when asked for (render/heat_legend.h,
// on the CPU after any renderer), then the encoding (render/png.h) at the fast level thumbnails use.
#pragma once

#include <optional>
#include <string>

#include "core/common/result.h"
#include "core/render/scene.h"

namespace animspace::thumbnail {

struct ThumbnailPng {
  std::string png;                 // 8-bit RGBA PNG
  bool heat_legend_drawn = false;  // false when no legend was asked for or it did not fit
};

// `legend_max`: the scale the scene's heat map used (Scene::heat_max, ≥ 0, finite), or nullopt
// for no legend. Errors: render::encode_png's (kInvalidArgument for an empty image).
Result<ThumbnailPng> encode_thumbnail(render::Image image, std::optional<double> legend_max);

}  // namespace animspace::thumbnail
