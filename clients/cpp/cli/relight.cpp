#include "clients/cpp/cli/relight.h"

#include <cstdio>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/number_checks.h"
#include "core/common/atomic_file.h"

namespace animspace::cli {

CLI::App* add_relight(CLI::App& app, RelightArgs& a) {
  auto* cmd = app.add_subcommand(
      "relight",
      "Illumination models: move a point light along a path and save each frame as a PNG; every frame is answered "
      "from key points by the daemon (Meyer & Anderson 2007 §3.2) and drawn by its render thread");
  cmd->add_option("model", a.model, "Model name (server engine ILLUMINATION, e.g. the demo's cornell)")->required();
  cmd->add_option("--from", a.from, "The light's first position x y z (model units)")->expected(3)->required();
  cmd->add_option("--to", a.to, "The light's last position x y z (default: --from)")->expected(3);
  cmd->add_option("--frames", a.frames, "Frames along the path, both ends included (default: 8 with --to, else 1)")
      ->check(CLI::Range(1, 10000));
  cmd->add_option("-o,--output", a.output,
                  "PNG files to write: a pattern with one %d for the frame number (e.g. /tmp/relight-%02d.png), "
                  "or a .png name for a single frame")
      ->required();
  cmd->add_option("--version", a.version, "Model version (default: the served one)");
  cmd->add_option("--width", a.width, "Width, pixels")->capture_default_str();
  cmd->add_option("--height", a.height, "Height, pixels")->capture_default_str();
  cmd->add_option("--radiance", a.radiance,
                  "total: direct (computed by the server) + served indirect; indirect: the served indirect alone")
      ->check(CLI::IsMember({"total", "indirect"}))
      ->capture_default_str();
  cmd->add_option("--white", a.white, "Radiance drawn white (0: the 99th percentile of each frame)")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  auto* heat = cmd->add_flag("--heat", a.heat,
                             "Draw |full − served| instead, the full indirect illumination gathered by the server "
                             "(as slow as the full calculation; blue 0 → red at the scale, which each frame prints)");
  add_heat_scale_options(cmd, a.heat_scale, heat);
  return cmd;
}

int run_relight(const RelightArgs& a, Client& client, bool json) {
  const bool pattern = a.output.find('%') != std::string::npos;
  const int frames = a.frames > 0 ? a.frames : (a.to.empty() ? 1 : 8);
  if (!pattern && frames != 1) {
    return fail("relight", "-o " + a.output + ": " + std::to_string(frames) +
                               " frames need a file name pattern with %d (e.g. /tmp/relight-%02d.png)");
  }
  if (const std::string bad = check_output_extension(a.output, {".png"}, "relight writes PNGs"); !bad.empty()) {
    return fail("relight", bad);
  }
  const std::vector<double>& to = a.to.empty() ? a.from : a.to;
  nlohmann::json rows = nlohmann::json::array();
  for (int f = 0; f < frames; ++f) {
    const double t = frames == 1 ? 0.0 : static_cast<double>(f) / (frames - 1);
    v1::RenderThumbnailRequest request;
    request.mutable_model()->set_name(a.model);
    request.mutable_model()->set_version(a.version);
    request.set_width_px(a.width);
    request.set_height_px(a.height);
    auto* light = request.mutable_key_points()->mutable_light_set()->add_lights();
    for (int c = 0; c < 3; ++c) light->add_position((1 - t) * a.from[static_cast<size_t>(c)] + t * to[static_cast<size_t>(c)]);
    auto* view = request.mutable_illumination();
    view->set_radiance(a.radiance == "indirect" ? v1::IlluminationView::RADIANCE_INDIRECT
                                                : v1::IlluminationView::RADIANCE_TOTAL);
    view->set_white_radiance(a.white);
    view->set_heat_from_full_gather(a.heat);
    if (a.heat) set_heat_scale(a.heat_scale, request);
    const Thumbnail thumbnail = client.render_thumbnail(request);
    std::string path = a.output;
    if (pattern) {
      std::vector<char> name(a.output.size() + 32);
      std::snprintf(name.data(), name.size(), a.output.c_str(), f);
      path = name.data();
    }
    if (auto written = write_file_atomically(path, thumbnail.png); !written.ok()) {
      return fail("relight", written.error().message);
    }
    const char* status = thumbnail.pose ? cache_status_name(thumbnail.pose->status) : "?";
    const double e_key = thumbnail.pose ? thumbnail.pose->key_point_error : 0.0;
    if (json) {
      nlohmann::json row = {{"frame", f},
                            {"light", {light->position(0), light->position(1), light->position(2)}},
                            {"output", path},
                            {"cache_status", status},
                            {"key_point_error", e_key},
                            {"render_ms", thumbnail.render_ms}};
      if (a.heat) add_heat_scale_json(a.heat_scale, thumbnail, row);
      rows.push_back(row);
    } else {
      std::printf("frame %d: light (%.3f, %.3f, %.3f): %s, e_key %.4g%s → %s\n", f, light->position(0),
                  light->position(1), light->position(2), status, e_key,
                  a.heat ? ("; heat map: " + heat_scale_text(a.heat_scale, thumbnail, "|full − served|")).c_str() : "",
                  path.c_str());
    }
  }
  if (json) print_json({{"model", a.model}, {"frames", rows}});
  return 0;
}

}  // namespace animspace::cli
