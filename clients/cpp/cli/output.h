// What the command line prints: JSON for scripts (--json) and progress bars for long work.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include <google/protobuf/map.h>
#include <google/protobuf/message.h>
#include <nlohmann/json.hpp>

#include "core/common/progress.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::cli {

// One JSON document on stdout, indented, ending in a newline.
void print_json(const nlohmann::json& document);

// What a retrain changed for the soft cache (issue #21): ε before → after (recalibrated on every
// retrain) and the hit rate of the version retrained from and of the new one on the new training
// frames. Shared by `retrain` (the RPC) and `retrain-offline`.
void print_soft_cache_change(double previous_epsilon_min, double epsilon_min, double previous_epsilon_max,
                             double epsilon_max, long training_frames, double previous_hit_rate, double hit_rate);

// The soft cache's operating curve (issue #22): for each offered false-hit rate δ, the error ratio,
// ε_min and the cross-validated hit rate and miss recall on the model's calibration samples, the
// chosen δ marked. Printed by `train-pmsc` and `calibrate`; `tolerance` in model units, `folds`
// the calibration folds per family (TrainingOptions::calibration_folds).
void print_operating_curve(const pmsc::PmscModel& model, double tolerance, int folds);
nlohmann::json operating_curve_json(const pmsc::PmscModel& model, double tolerance);

// What `describe` says of how a PMSC model's ε was chosen, from its metadata: the false-hit rate δ
// and error ratio of a conformal calibration (pmsc format 2), or that the model predates it
// (format 1: ε from the worst held-out ratio, with no stated false-hit rate).
std::string calibration_label(const google::protobuf::Map<std::string, std::string>& metadata);

// A protobuf message as JSON with the .proto field names (what `--json` prints for RPC answers).
nlohmann::json proto_json(const google::protobuf::Message& message);

// A one-line progress bar on stderr, drawn only when stderr is a terminal, so that logs, pipes
// and `--json` output stay clean. Redraws at most ten times a second; `finish()` (or the
// destructor) ends the line.
class ProgressBar {
 public:
  ProgressBar(std::string label, uint64_t total);
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  ~ProgressBar();

  // `done` of `total` steps; `detail` is shown after the count (e.g. "hit rate 93%").
  void update(uint64_t done, const std::string& detail = "");
  // Work whose total is only known once it starts (a simplifier's collapse count).
  void set_total(uint64_t total) { total_ = total; }
  void finish();

  bool enabled() const { return enabled_; }

 private:
  void draw(const std::string& detail);

  std::string label_;
  uint64_t total_ = 0;
  uint64_t done_ = 0;
  bool enabled_ = false;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
};

// A core ProgressCallback drawing one ProgressBar per stage, labelled "<command>: <stage>".
ProgressCallback progress_bars(const std::string& command);

}  // namespace animspace::cli
