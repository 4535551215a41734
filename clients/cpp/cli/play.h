// `animspace play`: stream a sequence's key points to a PMSC model (PoseService.StreamKeyPoints)
// and report hits, blends and misses — the soft cache seen from a posing engine's side. With
// --complete, every blend or miss is completed with the frame's full values (client fail-through,
// CompleteMiss), which logs it for the next `animspace retrain`. With --coordinates the answers come
// as subspace coordinates and the client reconstructs every pose (clients/cpp/coordinates.h,
// the basis cached on disk), reporting its cost and each pose's largest distance from the frame.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "clients/cpp/client.h"

namespace animspace::cli {

struct PlayArgs {
  std::string model;
  uint64_t version = 0;
  std::string sequence;      // folder (reference.obj + frames.pc2, OBJ frames), mesh + --pc2, or a model.anim
  std::string pc2;
  std::string select = "::";
  bool complete = false;
  bool coordinates = false;
  std::string basis_cache;  // empty: coordinates.h's default directory
  bool verbose = false;
};

CLI::App* add_play(CLI::App& app, PlayArgs& args);
int run_play(const PlayArgs& args, Client& client, bool json);

}  // namespace animspace::cli
