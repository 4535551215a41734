// `animspace thumbnail`: a PNG of a served model drawn by the daemon's render thread
// (RenderService.RenderThumbnail) — its rest pose, a stored frame, or a sequence frame's key
// points through the soft cache with the key points and the error heat map drawn over it; a
// model's texture atlas as a checker.
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "clients/cpp/cli/heat_scale.h"
#include "clients/cpp/client.h"

namespace animspace::cli {

struct ThumbnailArgs {
  std::string model;
  uint64_t version = 0;
  std::string output;
  uint32_t width = 256;
  uint32_t height = 256;
  int frame = -1;            // the model's stored frame (sequence_frame)
  std::string sequence;      // key points of a frame of this sequence (PMSC models)
  std::string pc2;
  int sequence_frame = 0;
  bool key_points = false;   // draw the key points
  bool heat = false;         // heat map of |full − returned| (needs --sequence)
  HeatScaleArgs heat_scale;
  bool wireframe = false;
  bool checker = false;         // the texture atlas as a checker (texture_checker)
  int32_t checker_squares = 0;  // squares per unit of texture coordinate; 0: the server's default
  bool chart_borders = false;   // the atlas's chart borders drawn over the checker
  bool lambert = false;
  uint32_t samples = 4;
  std::vector<float> background;
  float tolerance_px = 0;
  std::vector<float> eye, target, up;
  float fov_degrees = 0;     // vertical, degrees (the API's camera.vertical_fov_rad is radians)
};

CLI::App* add_thumbnail(CLI::App& app, ThumbnailArgs& args);
int run_thumbnail(const ThumbnailArgs& args, Client& client, bool json);

}  // namespace animspace::cli
