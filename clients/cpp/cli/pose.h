// `animspace pose`: evaluate skeleton poses through a served animation-space model
// (SkinningService.EvaluateSkeletonPose, v = Σ_j G_j p_j, Merry 2007 §3.1) and write the posed
// sequence as a point cache (.pc2), or one posed mesh with normals (.obj/.ply/.glb/.gltf; the faces
// come from the level's GetLod answer).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "clients/cpp/client.h"

namespace animspace::cli {

struct PoseArgs {
  std::string model;
  uint64_t version = 0;
  std::string pose_file;              // B × 12 numbers per pose, several poses one after another
  std::string pose_space = "global";  // "global": G_j; "local": joint transforms L_j
  uint32_t lod_level = 0;
  bool normals = false;
  std::string output;  // "" = print a summary only
};

CLI::App* add_pose(CLI::App& app, PoseArgs& args);
int run_pose(const PoseArgs& args, Client& client, bool json);

}  // namespace animspace::cli
