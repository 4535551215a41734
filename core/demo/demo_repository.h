// The bundled demo model repository: the bending arm (core/demo/bending_arm.h) as a model the
// daemon serves, so that a fresh install has something to list, pose and train on.
//
// Layout: <repository>/arm/1/model.anim, a model container (core/container/model_container.h) of
// kind "mesh_sequence" holding the rest mesh, the two-bone rig with its skinning weights, and one
// loop of the demo animation posed by the expensive rig — the training data for PMSC subspaces
// (seed 000 §3) and animation-space fitting (Merry 2007 §4.1).
#pragma once

#include <filesystem>
#include <string_view>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/demo/bending_arm.h"

namespace animspace::demo {

inline constexpr std::string_view kDemoModelName = "arm";
inline constexpr int kDemoModelVersion = 1;
inline constexpr std::string_view kDemoModelFileName = "model.anim";
inline constexpr int kDemoFrames = 120;

// The demo model, B = 2 bones, N vertices, F frames (>= 1). Metadata: kind = "mesh_sequence",
// description, generator, units, up_axis = "y". Sections:
//   mesh.rest_points          float32 N×3     rest positions V̂
//   mesh.faces                int32   #F×3    counter-clockwise seen from outside
//   skeleton.parents          int32   B×1     -1 for the root (upper arm), then 0
//   skeleton.rest_transforms  float64 B×16    Ĝ_j, bone to world, row-major 4×4
//   skinning.weights          float32 N×B     rows sum to 1
//   sequence.frames           float32 F×3N    frame f's expensive-rig points x0 y0 z0 x1 …
//   sequence.bone_transforms  float64 F×16B   frame f's G_0 … G_{B-1}, each row-major 4×4
//   sequence.pose_parameters  float64 F×3     elbow, shoulder, twist (radians; see ArmPose)
container::ModelContainer make_demo_container(const BendingArmOptions& options = {},
                                              int frames = kDemoFrames);

// The path of the demo model's file inside `repository`.
std::filesystem::path demo_model_path(const std::filesystem::path& repository);

// Writes the demo model (default options, kDemoFrames frames) to demo_model_path(repository),
// creating directories as needed; the file is replaced atomically if it exists. Errors: kIo
// naming the directory that could not be created, or the container writer's error.
Status write_demo_repository(const std::filesystem::path& repository);

}  // namespace animspace::demo
