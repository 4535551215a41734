#include "clients/cpp/cli/train_illumination.h"

#include <cstdio>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/number_checks.h"
#include "core/illumination/surface.h"

namespace animspace::cli {

CLI::App* add_train_illumination(CLI::App& app, TrainIlluminationArgs& a) {
  auto* cmd = app.add_subcommand(
      "train-illumination",
      "Offline: gather the Cornell box's indirect illumination for a grid of point lights and train a PMSC model "
      "of it that the daemon serves, relighting from key points (Meyer & Anderson 2007 §3.2)");
  cmd->add_option("--points", a.points, "Surface sample points (vertices) of the tessellated box, about")
      ->check(CLI::Range(100, 5000000))
      ->capture_default_str();
  cmd->add_option("--samples", a.samples, "Final-gather rays per point (the full calculation's cost)")
      ->check(CLI::Range(1, 65536))
      ->capture_default_str();
  cmd->add_option("--seed", a.seed, "Seed of the per-point ray directions")->capture_default_str();
  cmd->add_flag("--direct-from-vertices,!--shadow-ray-per-hit", a.direct_from_vertices,
                "Each gather ray's hit reads the direct light interpolated from its triangle's vertices, computed "
                "once per light (the lights share the rays), instead of tracing a shadow ray from the hit");
  cmd->add_flag("--cell-average,!--vertex-gather", a.cell_average,
                "Each vertex's rays leave from points spread over its cell (the part of its triangles where it "
                "weighs the most), so that its value is the mean over the area it stands for, not the value at the "
                "vertex alone");
  cmd->add_option("--cell-shadow-rays", a.cell_shadow_rays,
                  "With --direct-from-vertices: the direct light stored at a vertex is the mean over its cell, from "
                  "this many shadow rays per light where a shadow's edge crosses the cell (0: the vertex's own shadow "
                  "ray; default: " +
                      std::to_string(illumination::IlluminationTrainingOptions{}.gather.cell_shadow_rays) + ")")
      ->check(CLI::Range(0, 4096));
  cmd->add_option("--filter-neighbours", a.filter_neighbours,
                  "Surface filter of each gathered frame (and of the daemon's full calculation): each point's "
                  "irradiance averaged over about this many neighbours on the surface (0: no filter)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  cmd->add_option("--filter-min-normal-cosine", a.filter_min_normal_cosine,
                  "Surface filter: neighbours whose normals make a smaller cosine with the point's are left out")
      ->check(CLI::Range(-0.999999, 1.0))
      ->capture_default_str();
  cmd->add_flag("--filter-linear,!--filter-mean", a.filter_linear,
                "Surface filter: fit a plane to the neighbours' irradiance (keeps gradients by borders and creases) "
                "instead of averaging it");
  cmd->add_option("--key-samples", a.key_samples,
                  "Gather rays per key point, unfiltered, when the daemon gathers the keys from a request's light (0: the "
                  "key points' filter support at --samples rays, filtered: the values the model learned; measured "
                  "better in docs/BENCHMARKS.md \"Issue #38 item 1\")")
      ->check(CLI::Range(0, 65536))
      ->capture_default_str();
  cmd->add_option("--lights-x", a.lights_x, "Training lights across the room (x)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--lights-z", a.lights_z, "Training lights along the room (z)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--drop", a.drop, "Light plane below the ceiling, fraction of the room's height")
      ->check(CLI::Range(0.001, 0.999))
      ->capture_default_str();
  cmd->add_option("--inset", a.inset, "Light grid inset from the walls, fraction of width and depth")
      ->check(CLI::Range(0.0, 0.499))
      ->capture_default_str();
  cmd->add_option("--tolerance", a.tolerance,
                  "Soft cache: ε is calibrated so that frames with a point error above this fraction of the "
                  "frame's own largest radiance are flagged (of the training frames' median largest radiance "
                  "with --absolute-tolerance)")
      ->check(tools::kPositive)
      ->capture_default_str();
  cmd->add_flag("--absolute-tolerance", a.absolute_tolerance,
                "One tolerance in radiance units for every frame (models before issue #38), instead of one "
                "relative to each frame's radiance: a dim light then always hits and a bright one misses");
  cmd->add_option("--error-bound", a.error_bound,
                  "Key selection stops when every training point is within this fraction of the radiance scale")
      ->check(tools::kPositive)
      ->capture_default_str();
  cmd->add_option("--false-hit-rate", a.false_hit_rate, "Soft cache: δ of the conformal calibration")
      ->check(CLI::Range(1e-6, 0.999999))
      ->capture_default_str();
  cmd->add_option("--basis", a.basis, "Subspace dimension M (default: chosen by --basis-slack); M < lights");
  cmd->add_option("--basis-slack", a.basis_slack,
                  "M = the smallest whose error on held-out lights is within (1 + this) of the best (0: M from the "
                  "error bound, the measured best with --filter-neighbours 0)")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  cmd->add_option("--max-key-points", a.max_key_points, "Key point budget")->capture_default_str();
  cmd->add_option("--regions", a.regions, "Regions for local fail-through (0 = none)")->capture_default_str();
  cmd->add_option("--description", a.description, "One-line description stored in the model");
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_train_illumination(const TrainIlluminationArgs& a, bool json) {
  auto engine = illumination::IlluminationEngine::create(illumination::cornell_box({a.points}));
  if (!engine) return fail("train-illumination", engine.error().message);
  illumination::IlluminationTrainingOptions options;
  const illumination::LightGrid grid{a.lights_x, a.lights_z, a.drop, a.inset};
  for (const Eigen::Vector3d& position : illumination::light_grid(illumination::cornell_room(), grid)) {
    options.lights.push_back({position, Eigen::Vector3d::Ones()});
  }
  options.gather.samples = a.samples;
  options.gather.seed = a.seed;
  options.gather.direct_from_vertices = a.direct_from_vertices;
  options.gather.cell_average = a.cell_average;
  if (a.cell_shadow_rays >= 0) {
    options.gather.cell_shadow_rays = a.cell_shadow_rays;
  } else if (!a.direct_from_vertices) {
    options.gather.cell_shadow_rays = 0;  // they make the vertices' stored direct light
  }
  options.filter = {a.filter_neighbours, a.filter_min_normal_cosine, a.filter_linear};
  options.key_samples = a.key_samples;
  options.tolerance_fraction = a.tolerance;
  options.relative_tolerance = !a.absolute_tolerance;
  options.error_bound_fraction = a.error_bound;
  options.pmsc.basis_size = a.basis;
  options.pmsc.held_out_basis_slack = a.basis_slack;
  options.pmsc.max_key_points = a.max_key_points;
  options.pmsc.region_count = a.regions;
  options.pmsc.false_hit_rate = a.false_hit_rate;
  options.pmsc.progress = progress_bars("train-illumination");
  const int points = (*engine)->point_count();
  const std::string description =
      a.description.empty() ? "Cornell box indirect illumination: " + std::to_string(points) + " points, " +
                                  std::to_string(options.lights.size()) + " training lights, " +
                                  std::to_string(a.samples) + " gather rays"
                            : a.description;
  illumination::IlluminationTrainingReport report;
  auto container = illumination::train_illumination(**engine, options, description, &report);
  options.pmsc.progress = nullptr;  // ends the last bar's line before the report
  if (!container) return fail("train-illumination", container.error().message);
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, *container); !written.ok()) {
    return fail("train-illumination", written.error().message);
  }
  const pmsc::TrainingReport& r = report.pmsc;
  if (json) {
    print_json({{"output", path.string()},
                {"points", points},
                {"lights", options.lights.size()},
                {"samples", a.samples},
                {"direct_from_vertices", a.direct_from_vertices},
                {"cell_average", a.cell_average},
                {"cell_shadow_rays", options.gather.cell_shadow_rays},
                {"basis", r.basis_size},
                {"key_points", r.key_points},
                {"radiance_scale", report.radiance_scale},
                {"relative_tolerance", options.relative_tolerance},
                {"peak_to_rms_ratio", report.peak_to_rms_ratio},
                {"max_training_error", r.max_training_error},
                {"converged", r.converged},
                {"gather_seconds", report.gather_seconds},
                {"train_seconds", r.seconds},
                {"pca_seconds", r.pca_seconds},
                {"key_selection_seconds", r.key_selection_seconds},
                {"calibration_seconds", r.calibration_seconds},
                {"seconds", report.gather_seconds + r.seconds}});
  } else {
    std::printf("gathered %zu frames of %d points (%d rays each) in %.2f s; radiance scale %.4g\n",
                options.lights.size(), points, a.samples, report.gather_seconds, report.radiance_scale);
    std::printf("trained in %.2f s (PCA and M %.2f s, key points %.2f s, calibration %.2f s): basis M = %d, %d key "
                "points; max training error %.4g (%.2f%% of the scale)\n",
                r.seconds, r.pca_seconds, r.key_selection_seconds, r.calibration_seconds, r.basis_size, r.key_points, r.max_training_error,
                100 * r.max_training_error / report.radiance_scale);
    if (options.relative_tolerance) {
      std::printf("a HIT is within %.3g of each frame's largest radiance (%.3g × its RMS radiance; the training "
                  "frames' median peak/RMS is %.3g)\n",
                  options.tolerance_fraction, options.tolerance_fraction * report.peak_to_rms_ratio,
                  report.peak_to_rms_ratio);
    }
    std::printf("wrote %s\n", path.c_str());
    print_serving_hint(a.model);
  }
  return 0;
}

}  // namespace animspace::cli
