// `animspace export-rig`: any animation-space model file — fitted, imported from a rig
// (import-rig), subdivided, or one of its levels of detail (build-lod) — written as a glTF 2.0
// skinned character: its linear blend rig (animation_space::linear_blend_rig), the stored
// training poses as the animation, and how far that rig is from the model over those poses; or an
// articulated pmsc model as its bones and residual morph targets (pmsc/articulated_rig.h).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace animspace::cli {

struct ExportRigArgs {
  std::string input;
  int level = 0;  // a level of detail of the model (0 = full detail)
  double frames_per_second = 24;
  std::string output;
};

CLI::App* add_export_rig(CLI::App& app, ExportRigArgs& args);
int run_export_rig(const ExportRigArgs& args, bool json);

}  // namespace animspace::cli
