// `animspace train-pmsc`: train a PMSC / KPSA model from a mesh sequence and write a servable
// model version.
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/pmsc/train.h"

namespace animspace::cli {

struct TrainPmscArgs {
  std::string sequence;        // folder (reference.obj + frames.pc2, or OBJ frames) or reference mesh
  std::string pc2;             // point cache when `sequence` is a mesh file
  std::string control;         // cross-PMSC: control sequence (folder or mesh; --control-pc2)
  std::string control_pc2;
  std::string select = "::";   // frames, Python slice start:stop:step
  double error_bound_diag = 0.0025;
  double tolerance_diag = 0.01;
  double false_hit_rate = pmsc::TrainingOptions{}.false_hit_rate;
  int basis = 0;
  int max_key_points = 200;
  double held_out_key_slack = pmsc::TrainingOptions{}.held_out_key_slack;
  int block = 12;
  std::vector<int> fiducials;
  int grid = 0;
  bool align = false;
  std::string subspace = "linear";  // pmsc::SubspaceKind by name
  int bones = 0;                    // articulated: 0 by rule
  int residual_components = -1;     // articulated: −1 by the held-out rule
  int regions = 8;
  double check_point_fraction = pmsc::kCheckPointFraction;
  std::string description;
  std::string output;          // model.anim path, or a repository with --model
  std::string model;
  unsigned version = 0;        // 0: next free version
};

CLI::App* add_train_pmsc(CLI::App& app, TrainPmscArgs& args);
int run_train_pmsc(const TrainPmscArgs& args, bool json);

}  // namespace animspace::cli
