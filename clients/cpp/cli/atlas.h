// `animspace atlas`: add a texture atlas balanced across poses to an animation-space model
// (issue #37; Merry 2007 ch. 5, core/atlas): charts segmented with the L2,2 metric, each flattened
// minimising L2 stretch across the model's pose distribution P, packed into the unit square. The
// atlas is stored as the container's atlas section; `export-lod --level 0` then writes the UVs
// (OBJ vt, PLY s t, glTF TEXCOORD_0), seams split into separate vertices.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "clients/cpp/cli/sampled_metrics.h"

namespace animspace::cli {

struct AtlasArgs {
  std::string input;      // model.anim of an animation-space model with faces
  int charts = 0;         // seeds; 0: two per moving bone (atlas::default_chart_count)
  bool rest_pose = false; // stretch measured in the rest pose only (the static-unwrap baseline)
  SamplePoseArgs poses;  // metrics when the model stores none (an imported rig)
  std::string output;
  std::string model;
  unsigned version = 0;
};

CLI::App* add_atlas(CLI::App& app, AtlasArgs& args);
int run_atlas(const AtlasArgs& args, bool json);

}  // namespace animspace::cli
