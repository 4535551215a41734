// `animspace retrain-offline`: the nightly retrain of a scaled-out deployment, run next to the
// repository rather than through one replica's Retrain RPC. It folds the misses logged by every
// replica (each writes <miss-log-dir>/<model>.misses; their directories sit under one root) into
// the model's training frames, retrains (Meyer & Anderson 2007 §2.4: a completed miss is exactly
// the example the subspace lacked), and publishes the next version atomically into the
// repository, where every replica's --poll-interval-s picks it up.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace animspace::cli {

struct RetrainOfflineArgs {
  std::string repository;
  std::string model;
  uint64_t version = 0;     // start from this version; 0 = the newest
  std::string miss_logs;    // root searched recursively for <model>.misses
  double error_bound = 0;   // > 0 overrides the stored bound (model units)
  int max_key_points = 0;   // > 0 overrides the stored key budget
  uint64_t min_misses = 1;  // publish only with at least this many new completed misses
  bool dry_run = false;
};

CLI::App* add_retrain_offline(CLI::App& app, RetrainOfflineArgs& args);
int run_retrain_offline(const RetrainOfflineArgs& args, bool json);

}  // namespace animspace::cli
