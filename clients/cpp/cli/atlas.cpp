#include "clients/cpp/cli/atlas.h"

#include <chrono>
#include <cstdio>
#include <numbers>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "core/animspace/animspace_io.h"
#include "core/atlas/atlas.h"
#include "core/atlas/atlas_io.h"
#include "core/common/format.h"

namespace animspace::cli {

namespace as = animation_space;

CLI::App* add_atlas(CLI::App& app, AtlasArgs& a) {
  auto* cmd = app.add_subcommand(
      "atlas",
      "Offline: add a texture atlas balanced across poses to an animation-space model (Merry 2007 ch. 5): charts "
      "segmented with the L2,2 metric, each flattened minimising L2 stretch across the model's poses without "
      "flipping a triangle, packed into the unit square; write a model version with the atlas section");
  cmd->add_option("input", a.input, "An animation-space model.anim with faces (fit, import-rig, build-lod)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--charts", a.charts,
                  "Charts to grow before the disc repair and the stretch splits (default: two per moving bone)")
      ->check(CLI::Range(1, 1000000));
  cmd->add_flag("--rest-pose", a.rest_pose,
                "Measure stretch in the rest pose only, as a static unwrap does (the baseline; no metrics needed)");
  add_sample_pose_options(cmd, a.poses);
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_atlas(const AtlasArgs& a, bool json) {
  auto in = container::read_file(a.input);
  if (!in) return fail("atlas", in.error().message);
  auto model = as::load(*in, a.input);
  if (!model) return fail("atlas", model.error().message);
  if (model->faces.rows() == 0) return fail("atlas", a.input + ": the model has no faces to texture");
  container::ModelContainer out = *in;
  as::AnimationSpaceMetrics metrics;
  std::string metric_name = "poses";
  if (a.rest_pose) {
    auto rest = atlas::rest_pose_metrics(model->skeleton);
    if (!rest) return fail("atlas", rest.error().message);
    metrics = std::move(*rest);
    metric_name = "rest_pose";
  } else {
    auto stored = model_metrics(*in, *model, a.poses, a.input, out, "--rest-pose");
    if (!stored) return fail("atlas", stored.error().message);
    metrics = std::move(stored->metrics);
  }
  atlas::AtlasOptions options;
  options.chart_count = a.charts;
  const auto start = std::chrono::steady_clock::now();
  options.progress = progress_bars("atlas");
  auto built = atlas::build_atlas(*model, metrics, options);
  options.progress = nullptr;  // ends the last bar's line before the report
  if (!built) return fail("atlas", a.input + ": " + built.error().message);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  atlas::store_atlas(built->atlas, metric_name, out);
  // Levels built under a previous atlas carry its UVs (lod.<l>.uvs), which the new charts make
  // stale: they are dropped, and build-lod stores the new ones.
  int stale_level_uvs = 0;
  for (const std::string& name : in->section_names()) {
    if (name.starts_with("lod.") && name.ends_with(".uvs")) {
      out.remove_section(name);
      ++stale_level_uvs;
    }
  }
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, out); !written.ok()) return fail("atlas", written.error().message);
  if (json) {
    print_json({{"output", path.string()},
                {"metric", metric_name},
                {"charts", built->atlas.chart_count},
                {"l2_stretch", built->l2},
                {"linf_stretch", built->linf},
                {"utilisation", built->utilisation},
                {"dropped_level_uvs", stale_level_uvs},
                {"seconds", seconds}});
  } else {
    std::printf("atlas (%s): %d charts, L2 stretch %.4f, L∞ %.3f (%s), utilisation %.3f, %.2f s\nwrote %s\n",
                metric_name.c_str(), built->atlas.chart_count, built->l2, built->linf,
                a.rest_pose ? "rest pose" : "across the model's poses", built->utilisation, seconds, path.c_str());
    print_serving_hint(a.model);
    if (stale_level_uvs > 0) {
      std::printf("dropped the UVs of %d levels of detail (made under the previous atlas); run build-lod for new "
                  "ones\n",
                  stale_level_uvs);
    }
  }
  return 0;
}

}  // namespace animspace::cli
