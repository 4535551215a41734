// `animspace relight`: an illumination model's room relit along a path (Meyer & Anderson 2007
// §3.2, Figs. 5 and 10): a point light moved from one position to another in N frames, each frame
// answered from key points by the daemon (it gathers the key points for the light and reconstructs
// every point; a blend or miss fails through to its full gather) and drawn by its render thread.
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "clients/cpp/cli/heat_scale.h"
#include "clients/cpp/client.h"

namespace animspace::cli {

struct RelightArgs {
  std::string model;
  uint64_t version = 0;
  std::vector<double> from, to;  // light positions, model units
  int frames = 0;                // 0: 8 along --from → --to, 1 without --to
  std::string output;            // a printf pattern with one %d (frame), or a single .png for one frame
  uint32_t width = 256;
  uint32_t height = 256;
  std::string radiance = "total";  // total | indirect
  float white = 0;                 // radiance drawn white (0: the server's default)
  bool heat = false;               // heat map of |full − served| with the server's full gather
  HeatScaleArgs heat_scale;
};

CLI::App* add_relight(CLI::App& app, RelightArgs& args);
int run_relight(const RelightArgs& args, Client& client, bool json);

}  // namespace animspace::cli
