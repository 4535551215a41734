// `animspace evaluate`: send a sequence's key points to a PMSC model in unary batches
// (PoseService.EvaluateKeyPoints) and compare what comes back with the frames themselves — the
// soft cache's verdicts next to the error it actually made — optionally writing the returned
// sequence as a point cache. `play` is the streaming twin that does not fetch the points.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "clients/cpp/client.h"

namespace animspace::cli {

struct EvaluateArgs {
  std::string model;
  uint64_t version = 0;
  std::string sequence;  // folder (reference.obj + frames.pc2, OBJ frames), mesh + --pc2, or a model.anim
  std::string pc2;
  std::string select = "::";
  uint32_t batch = 32;
  bool region_errors = false;
  bool local_fail_through = false;
  bool without_check_points = false;  // key values only, as a client from before issue #35
  bool verbose = false;  // accepted for scripts written when one line per frame needed -v
  bool quiet = false;    // the summary only
  std::string output;    // .pc2 of the returned points, "" = none
};

CLI::App* add_evaluate(CLI::App& app, EvaluateArgs& args);
int run_evaluate(const EvaluateArgs& args, Client& client, bool json);

}  // namespace animspace::cli
