// The heat map's scale on the command line, shared by `thumbnail --heat` (|full − returned| of a
// sequence frame) and `relight --heat` (|full − served| against the server's full gather): the
// error drawn red (RenderThumbnailRequest.heat_max) and the legend drawn with it
// (show_heat_legend), and how the command reports the scale the server used.
#pragma once

#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"

namespace animspace::cli {

struct HeatScaleArgs {
  float heat_max = 0;        // the error drawn red, model units (0: the server's default)
  bool heat_legend = false;  // draw the scale's colour bar with its numbers
};

// --heat-max and --heat-legend, each needing `heat` (the command's --heat flag).
void add_heat_scale_options(CLI::App* cmd, HeatScaleArgs& a, CLI::Option* heat);
void set_heat_scale(const HeatScaleArgs& a, v1::RenderThumbnailRequest& request);
// heat_max_error, heat_scale_max and (with --heat-legend) heat_legend_drawn.
void add_heat_scale_json(const HeatScaleArgs& a, const Thumbnail& thumbnail, nlohmann::json& out);
// "largest <difference> 0.0123, red at 0.02 (the model's error tolerance …)", and whether the
// legend did not fit.
std::string heat_scale_text(const HeatScaleArgs& a, const Thumbnail& thumbnail, const char* difference);

}  // namespace animspace::cli
