#include "core/thumbnail/thumbnail_png.h"

#include <utility>

#include "core/render/heat_legend.h"
#include "core/render/png.h"

namespace animspace::thumbnail {

Result<ThumbnailPng> encode_thumbnail(render::Image image, std::optional<double> legend_max) {
  ThumbnailPng out;
  if (legend_max) out.heat_legend_drawn = render::draw_heat_legend(image, *legend_max);
  auto png = render::encode_png(image);
  if (!png) return png.error();
  out.png = std::move(*png);
  return out;
}

}  // namespace animspace::thumbnail
