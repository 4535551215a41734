#include "clients/cpp/cli/heat_scale.h"

#include <cstdio>

#include "clients/cpp/tools/number_checks.h"

namespace animspace::cli {

void add_heat_scale_options(CLI::App* cmd, HeatScaleArgs& a, CLI::Option* heat) {
  cmd->add_option("--heat-max", a.heat_max,
                  "With --heat: the error drawn red, model units (default: the model's error tolerance, the "
                  "per-point error its soft cache was calibrated to flag; else the image's largest error). Give "
                  "one value to compare images on one scale")
      ->check(tools::kNonNegative)
      ->needs(heat);
  cmd->add_flag("--heat-legend", a.heat_legend, "With --heat: draw the scale as a colour bar with its numbers")
      ->needs(heat);
}

void set_heat_scale(const HeatScaleArgs& a, v1::RenderThumbnailRequest& request) {
  request.set_heat_max(a.heat_max);
  request.set_show_heat_legend(a.heat_legend);
}

void add_heat_scale_json(const HeatScaleArgs& a, const Thumbnail& thumbnail, nlohmann::json& out) {
  out["heat_max_error"] = thumbnail.heat_max_error;
  out["heat_scale_max"] = thumbnail.heat_scale_max;
  if (a.heat_legend) out["heat_legend_drawn"] = thumbnail.heat_legend_drawn;
}

std::string heat_scale_text(const HeatScaleArgs& a, const Thumbnail& thumbnail, const char* difference) {
  char text[320];
  std::snprintf(text, sizeof text, "largest %s %.4g, red at %.4g (%s; model units)%s", difference,
                thumbnail.heat_max_error, thumbnail.heat_scale_max,
                a.heat_max > 0 ? "--heat-max" : "the model's error tolerance, or the largest error when it has none",
                a.heat_legend && !thumbnail.heat_legend_drawn ? "; the image is too small for the legend" : "");
  return text;
}

}  // namespace animspace::cli
