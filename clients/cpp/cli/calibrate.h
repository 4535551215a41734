// `animspace calibrate`: choose another point of a PMSC model's operating curve without
// retraining (issue #22). The model keeps its held-out calibration samples (pmsc format 2), so a
// new false-hit rate δ gives new thresholds ε (and per-region thresholds) at once; the choice is
// stored with the model and in its training options, so a retrain keeps it.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace animspace::cli {

struct CalibrateArgs {
  std::string input;           // model.anim
  double false_hit_rate = 0;   // δ, required
  std::string output;          // file, or repository with --model
  std::string model;
  unsigned version = 0;
};

CLI::App* add_calibrate(CLI::App& app, CalibrateArgs& args);
int run_calibrate(const CalibrateArgs& args, bool json);

}  // namespace animspace::cli
