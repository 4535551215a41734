#include "clients/cpp/cli/calibrate.h"

#include <cstdio>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "core/container/model_container.h"
#include "core/pmsc/pmsc_io.h"

namespace animspace::cli {

CLI::App* add_calibrate(CLI::App& app, CalibrateArgs& a) {
  auto* cmd = app.add_subcommand(
      "calibrate",
      "Offline: give a PMSC model another false-hit rate δ from its stored operating curve (no retraining) and write "
      "it as a new model file or version");
  cmd->add_option("model_file", a.input, "model.anim of a PMSC model")->required()->check(CLI::ExistingFile);
  cmd->add_option("--false-hit-rate", a.false_hit_rate,
                  "δ: at most this fraction of poses like the held-out training frames is called HIT with an "
                  "error above the tolerance")
      ->required()
      ->check(CLI::Range(1e-6, 0.999999));
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_calibrate(const CalibrateArgs& a, bool json) {
  const char* command = "calibrate";
  auto container = container::read_file(a.input);
  if (!container) return fail(command, container.error().message);
  auto model = pmsc::load(*container, a.input);
  if (!model) return fail(command, model.error().message);
  auto options = pmsc::load_training_options(*container, a.input);
  if (!options) return fail(command, options.error().message);
  const pmsc::SoftCacheThresholds before = model->epsilon;
  model->calibration.false_hit_rate = a.false_hit_rate;
  if (auto applied = pmsc::apply_calibration(*model, options->error_tolerance, options->blend_zone_ratio);
      !applied.ok()) {
    return fail(command, a.input + ": " + applied.error().message);
  }
  options->false_hit_rate = a.false_hit_rate;
  pmsc::store(*model, *container);
  pmsc::store_training_options(*options, *container);
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, *container); !written.ok()) return fail(command, written.error().message);
  if (json) {
    print_json({{"output", path.string()},
                {"false_hit_rate", a.false_hit_rate},
                {"error_ratio", model->calibration.error_ratio},
                {"previous_epsilon_min", before.epsilon_min},
                {"previous_epsilon_max", before.epsilon_max},
                {"epsilon_min", model->epsilon.epsilon_min},
                {"epsilon_max", model->epsilon.epsilon_max},
                {"operating_curve", operating_curve_json(*model, options->error_tolerance)}});
    return 0;
  }
  std::printf("soft cache ε [%.4g, %.4g] → [%.4g, %.4g]: false-hit rate δ = %g, error ratio %.3g\n",
              before.epsilon_min, before.epsilon_max, model->epsilon.epsilon_min, model->epsilon.epsilon_max,
              a.false_hit_rate, model->calibration.error_ratio);
  print_operating_curve(*model, options->error_tolerance, options->calibration_folds);
  std::printf("wrote %s\n", path.c_str());
  print_serving_hint(a.model);
  return 0;
}

}  // namespace animspace::cli
