#include "clients/cpp/cli/thumbnail.h"

#include <cstdio>
#include <numbers>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/number_checks.h"
#include "clients/cpp/tools/sequence_frames.h"
#include "core/common/atomic_file.h"

namespace animspace::cli {

CLI::App* add_thumbnail(CLI::App& app, ThumbnailArgs& a) {
  auto* cmd = app.add_subcommand(
      "thumbnail",
      "Draw a served model headless on the daemon (EGL) and save the PNG: the rest pose, a stored frame, or a "
      "sequence frame's key points through the soft cache, with key points, error heat map and wireframe overlays");
  cmd->add_option("model", a.model, "Model name")->required();
  cmd->add_option("-o,--output", a.output, "PNG file to write (.png)")->required();
  cmd->add_option("--version", a.version, "Model version (default: the served one)");
  cmd->add_option("--width", a.width, "Width, pixels")->capture_default_str();
  cmd->add_option("--height", a.height, "Height, pixels")->capture_default_str();
  auto* frame = cmd->add_option("--frame", a.frame, "Draw the model's own stored frame K (sequence.frames)")
                    ->check(tools::kNonNegative);
  auto* sequence = cmd->add_option("--sequence", a.sequence,
                                   "PMSC models: pose from the key points of a frame of this sequence (folder with "
                                   "reference.obj + frames.pc2, a mesh with --pc2, or a model.anim)");
  cmd->add_option("--pc2", a.pc2, "Point cache when --sequence is a mesh file");
  cmd->add_option("--sequence-frame", a.sequence_frame, "Which frame of --sequence")
      ->check(tools::kNonNegative)
      ->capture_default_str();
  cmd->add_flag("--key-points", a.key_points, "Draw the key points as dots (PMSC models)");
  auto* heat = cmd->add_flag("--heat", a.heat,
                             "Colour each point by |full − returned| (blue 0 → red at the scale): the soft cache's "
                             "error, from --sequence's full frame; prints the largest error and the scale")
                   ->needs(sequence);
  add_heat_scale_options(cmd, a.heat_scale, heat);
  cmd->add_flag("--wireframe", a.wireframe, "Draw the triangle edges");
  auto* checker = cmd->add_flag("--checker", a.checker,
                                "Draw the model's texture atlas as a checker (full detail; the model needs an atlas: "
                                "`animspace atlas`)")
                      ->excludes(heat);
  cmd->add_option("--checker-squares", a.checker_squares,
                  "With --checker: squares along one unit of texture coordinate (default 16)")
      ->check(tools::kPositive)
      ->needs(checker);
  cmd->add_flag("--chart-borders", a.chart_borders, "With --checker: draw the atlas's chart borders")->needs(checker);
  cmd->add_flag("--lambert", a.lambert, "Lambert shading instead of Blinn-Phong");
  cmd->add_option("--samples", a.samples, "Multisampling: 1, 2, 4 or 8")->capture_default_str();
  cmd->add_option("--background", a.background, "Background RGBA in [0, 1], e.g. --background 1 1 1 1")
      ->expected(4);
  cmd->add_option("--tolerance-px", a.tolerance_px,
                  "Animation-space models: draw the coarsest level of detail whose error stays under this many "
                  "pixels (eq. 7.2)");
  auto* eye =
      cmd->add_option("--eye", a.eye, "Camera position x y z (default: framed from the bounding box)")->expected(3);
  // The rest of the camera only means something with --eye: without it they would be ignored.
  cmd->add_option("--target", a.target, "With --eye: point looked at x y z (default 0 0 0)")->expected(3)->needs(eye);
  cmd->add_option("--up", a.up, "With --eye: up direction x y z (default 0 1 0)")->expected(3)->needs(eye);
  cmd->add_option("--fov-deg,--fov", a.fov_degrees,
                  "With --eye: vertical field of view in DEGREES, default 45 (the API's camera.vertical_fov_rad is "
                  "radians; the command line converts)")
      ->check(CLI::Range(1.0, 179.0))
      ->needs(eye);
  frame->excludes(sequence);
  return cmd;
}

int run_thumbnail(const ThumbnailArgs& a, Client& client, bool json) {
  if (const std::string bad = check_output_extension(a.output, {".png"}, "thumbnail writes a PNG"); !bad.empty()) {
    return fail("thumbnail", bad);
  }
  v1::RenderThumbnailRequest request;
  request.mutable_model()->set_name(a.model);
  request.mutable_model()->set_version(a.version);
  request.set_width_px(a.width);
  request.set_height_px(a.height);
  request.set_samples(a.samples);
  request.set_shading(a.lambert ? v1::RenderThumbnailRequest::SHADING_LAMBERT
                                : v1::RenderThumbnailRequest::SHADING_BLINN_PHONG);
  request.set_show_key_points(a.key_points);
  request.set_show_wireframe(a.wireframe);
  request.set_tolerance_px(a.tolerance_px);
  request.set_texture_checker(a.checker);
  request.set_checker_squares(a.checker_squares);
  request.set_show_chart_borders(a.chart_borders);
  for (float c : a.background) request.add_background_rgba(c);
  if (!a.eye.empty()) {
    auto* camera = request.mutable_camera();
    camera->mutable_eye()->Add(a.eye.begin(), a.eye.end());
    const std::vector<float> target = a.target.empty() ? std::vector<float>{0, 0, 0} : a.target;
    const std::vector<float> up = a.up.empty() ? std::vector<float>{0, 1, 0} : a.up;
    camera->mutable_target()->Add(target.begin(), target.end());
    camera->mutable_up()->Add(up.begin(), up.end());
    camera->set_vertical_fov_rad((a.fov_degrees > 0 ? a.fov_degrees : 45.0f) * std::numbers::pi_v<float> / 180);
  }
  if (a.frame >= 0) request.set_sequence_frame(static_cast<uint32_t>(a.frame));
  if (!a.sequence.empty()) {
    auto frames = tools::load_sequence_frames(a.sequence, a.pc2);
    if (!frames) return fail("thumbnail", frames.error().message);
    if (a.sequence_frame >= frames->rows()) {
      return fail("thumbnail", "--sequence-frame: expected 0.." + std::to_string(frames->rows() - 1) + ", got " +
                                   std::to_string(a.sequence_frame));
    }
    const KeyPoints keys = client.describe_key_points(a.model, a.version);
    const auto D = keys.channel_count;
    if (frames->cols() != static_cast<long>(keys.control_point_count) * D) {
      return fail("thumbnail", "the sequence has " + std::to_string(frames->cols() / std::max<long>(1, D)) +
                                   " points per frame, model '" + a.model + "' expects " +
                                   std::to_string(keys.control_point_count));
    }
    const std::span<const float> frame(frames->row(a.sequence_frame).data(), static_cast<size_t>(frames->cols()));
    const std::vector<float> values = keys.gather(frame);
    *request.mutable_key_points()->mutable_key_values() =
        make_point_array(values.data(), static_cast<uint32_t>(keys.indices.size()), D);
    if (!keys.check_point_indices.empty()) {
      const std::vector<float> checks = keys.gather_check_values(frame);
      *request.mutable_key_points()->mutable_check_values() =
          make_point_array(checks.data(), static_cast<uint32_t>(keys.check_point_indices.size()), D);
    }
    request.mutable_model()->set_version(keys.model_version);
    if (a.heat) {
      *request.mutable_full_values() = make_point_array(frame.data(), keys.control_point_count, D);
      set_heat_scale(a.heat_scale, request);
    }
  }

  const Thumbnail thumbnail = client.render_thumbnail(request);
  if (auto written = write_file_atomically(a.output, thumbnail.png); !written.ok()) {
    return fail("thumbnail", written.error().message);
  }
  if (json) {
    nlohmann::json out = {{"output", a.output},
                          {"width", thumbnail.width_px},
                          {"height", thumbnail.height_px},
                          {"bytes", thumbnail.png.size()},
                          {"model_version", thumbnail.model_version},
                          {"lod_level", thumbnail.lod_level},
                          {"render_ms", thumbnail.render_ms}};
    if (thumbnail.pose) {
      out["cache_status"] = cache_status_name(thumbnail.pose->status);
      out["key_point_error"] = thumbnail.pose->key_point_error;
    }
    if (a.heat) add_heat_scale_json(a.heat_scale, thumbnail, out);
    print_json(out);
    return 0;
  }
  std::string verdict;
  if (thumbnail.pose) {
    // %g, not to_string's six fixed decimals, which print a small e_key as 0.000000.
    char e_key[32];
    std::snprintf(e_key, sizeof e_key, "%.6g", static_cast<double>(thumbnail.pose->key_point_error));
    verdict = std::string("; soft cache ") + cache_status_name(thumbnail.pose->status) + ", e_key " + e_key;
  }
  std::printf("%s version %llu: %u×%u, level of detail %u, drawn and encoded in %.1f ms%s\nwrote %s (%zu bytes)\n",
              a.model.c_str(), static_cast<unsigned long long>(thumbnail.model_version), thumbnail.width_px,
              thumbnail.height_px, thumbnail.lod_level, thumbnail.render_ms, verdict.c_str(), a.output.c_str(),
              thumbnail.png.size());
  if (a.heat) std::printf("heat map: %s\n", heat_scale_text(a.heat_scale, thumbnail, "|full − returned|").c_str());
  return 0;
}

}  // namespace animspace::cli
