// `animspace subdivide`: subdivide an animation-space model in animation space (Merry 2007 §4.2,
// P' = P S; core/subdivision) and write it as a new model version, which poses exactly as the
// posed control mesh subdivided, in every pose, and loads, serves, builds levels and exports like
// any other animation-space model.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

namespace animspace::cli {

struct SubdivideArgs {
  std::string input;  // model.anim of an animation-space model
  int levels = 1;
  std::string scheme = "auto";     // subdivision::parse_scheme
  int64_t max_vertices = 0;        // 0: subdivision::kDefaultMaxVertices
  std::string output;
  std::string model;
  unsigned version = 0;
};

CLI::App* add_subdivide(CLI::App& app, SubdivideArgs& args);
int run_subdivide(const SubdivideArgs& args, bool json);

}  // namespace animspace::cli
