// `animspace build-lod`: add discrete levels of detail to an animation-space model version
// (Merry 2007 ch. 6, §7.3; core/lod), and `animspace export-lod`: write one level, posed, as a
// mesh file a render farm or a DCC tool opens (OBJ, PLY, glTF 2.0). Both work offline on model
// files; `animspace lod` asks a running animspaced for the level (LodService.GetLod) and writes
// the same kind of file.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "clients/cpp/cli/sampled_metrics.h"
#include "clients/cpp/client.h"

namespace animspace::cli {

struct BuildLodArgs {
  std::string input;  // model.anim of an animation-space model
  bool no_influence_simplification = false;
  bool no_placement = false;
  double influence_exchange = 1;  // lod::LevelBuildOptions::influence_exchange
  int max_levels = 16;
  double max_normal_deviation_degrees = 90;
  SamplePoseArgs poses;  // metrics when the model stores none (an imported rig)
  std::string output;
  std::string model;
  unsigned version = 0;
};

struct ExportLodArgs {
  std::string input;
  int level = -1;                // explicit level, or chosen from the view below
  double tolerance_px = 0;   // eq. 7.2: p
  double distance = 0;           // camera to bounding-sphere centre, model units
  double fov_degrees = 45;       // horizontal field of view 2θ
  double viewport_width_px = 1920;  // w
  int frame = -1;                // a stored training pose (sequence.bone_transforms); default rest
  std::string output;
};

CLI::App* add_build_lod(CLI::App& app, BuildLodArgs& args);
int run_build_lod(const BuildLodArgs& args, bool json);

CLI::App* add_export_lod(CLI::App& app, ExportLodArgs& args);
int run_export_lod(const ExportLodArgs& args, bool json);

struct LodArgs {
  std::string model;
  uint64_t version = 0;
  int64_t level = -1;            // explicit level, or one of the two choices below
  double tolerance_px = 0;   // eq. 7.2: p, with distance, fov and width
  double distance = 0;           // camera to bounding-sphere centre, model units
  double fov_degrees = 45;       // horizontal field of view 2θ
  uint32_t viewport_width_px = 1920;  // w
  uint32_t max_vertices = 0;     // the finest level with at most this many vertices
  // Pose: a text file of B × 12 numbers, each bone's top three matrix rows, row-major (the
  // SkeletonPose.transforms layout); '#' starts a comment. Default: the rest pose.
  std::string pose_file;
  std::string pose_space = "global";  // "global": G_j; "local": joint transforms L_j
  uint32_t vertices_per_chunk = 0;    // 0: the server's default
  bool texture_coordinates = false;   // the model's atlas at the level, written with seams split
  int deadline_s = 600;
  std::string output;
};

// Online: LodService.GetLod in FORM_POSED, written with mesh_io::write_posed_mesh.
CLI::App* add_lod(CLI::App& app, LodArgs& args);
int run_lod(const LodArgs& args, Client& client, bool json);

}  // namespace animspace::cli
