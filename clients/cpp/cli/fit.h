// `animspace fit`: turn a mesh sequence (any geometry cache) into an animation-space model
// version (skinning decomposition, then Merry 2007 §4.1's refit; core/animspace/fit_sequence.h),
// optionally also a glTF 2.0 skinned character with the sequence as its animation, and
// `animspace import-rig`: convert a linear-blend-skinned rig (libigl TGF + DMAT, or a glTF 2.0
// skin) to animation space exactly (§3.1).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

namespace animspace::cli {

struct FitArgs {
  std::string sequence;  // folder (reference.obj + frames.pc2, or OBJ frames) or reference mesh
  std::string pc2;
  std::string select = "::";
  // Frames the fit does not see, to report the error a new shot of the character would get
  // (empty: none).
  std::string test_select;
  int bones = 20;
  double edge_regularisation = 0.005;
  double vertex_regularisation = 1e-6;
  int rings = 1;
  int max_influences = 4;
  int iterations = 50;           // skinning decomposition: at most this many alternations
  double smoothness = 1e-4;      // μ of the weight solve (skinning_weights.h)
  int refinement_rounds = 3;     // animation space: motions ↔ model rounds
  bool first_pass = false;       // the pipeline before the decomposition (baseline)
  bool linear_blend = false;
  std::string export_path;       // .glb / .gltf skinned character
  double frames_per_second = 24;
  std::string description;
  std::string output;
  std::string model;
  unsigned version = 0;
};

struct ImportRigArgs {
  std::string mesh;  // rest mesh (libigl rigs)
  std::string tgf;
  std::string dmat;
  std::string gltf;
  std::string description;
  // Each vertex's smallest weights, up to this total, are dropped and the rest renormalised
  // (animation_space::WeightOptions::drop_budget).
  double drop_weights = 1e-4;
  std::string output;
  std::string model;
  unsigned version = 0;
};

CLI::App* add_fit(CLI::App& app, FitArgs& args);
int run_fit(const FitArgs& args, bool json);

CLI::App* add_import_rig(CLI::App& app, ImportRigArgs& args);
int run_import_rig(const ImportRigArgs& args, bool json);

}  // namespace animspace::cli
