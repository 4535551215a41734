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

#include "core/common/progress.h"
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

// Names of the PMSC demo models trained from the arm's frames. Both store their training options
// (pmsc.options.*), so the server can retrain them.
inline constexpr std::string_view kDemoPmscModelName = "arm-pmsc";
inline constexpr std::string_view kDemoCrossPmscModelName = "arm-cross-pmsc";

// The arm as a PMSC model (Meyer & Anderson 2007 §2): trained on every other frame of the demo
// animation posed by the expensive rig, so the frames in between are poses the soft cache has not
// seen. Key selection bound 0.25% and soft-cache tolerance 1% of the rest mesh's diagonal.
// Errors: the trainer's (none are expected for the built-in data).
Result<container::ModelContainer> make_demo_pmsc_container(int frames = kDemoFrames);

// Cross-PMSC (2007 §3.1): key points of the cheap linear-blend-skinned arm drive the expensive
// rig's mesh (biceps bulge and elbow correction included) — a posing engine that can only afford
// LBS gets the expensive deformation. Fail-through is impossible for it.
Result<container::ModelContainer> make_demo_cross_pmsc_container(int frames = kDemoFrames);

inline constexpr std::string_view kDemoAnimationSpaceModelName = "arm-animspace";

// The arm as an animation-space model (Merry 2007 §4.1): fitted by least squares, with edge
// regularisation δ = 0.02 (the thesis's arm, §8.2), to every other frame of the expensive rig with
// the rig's own bone transforms. Bone 0 is a fixed root, 1 the upper arm, 2 the forearm; every
// vertex may be influenced by both arm bones, so the fit can learn the biceps bulge and the
// elbow's kept volume as far as they are linear in the bone matrices — which LBS cannot (§2.2.2).
// The training frames and their bone transforms are kept (sequence.frames,
// sequence.bone_transforms) for refitting. Errors: the fitter's (none expected).
Result<container::ModelContainer> make_demo_animation_space_container(int frames = kDemoFrames);

inline constexpr std::string_view kDemoPmscEngineModelName = "arm-pmsc-engine";

// A PMSC soft cache in front of a posing engine (Meyer & Anderson 2007 §2.4 with the full
// calculation on the server): trained, with the arm-pmsc options, on the arm-animspace model's
// own output at its stored (even-frame) bone transforms, and carrying that animation-space model
// as its posing engine (pmsc::attach_posing_engine). On a blend or miss the server evaluates the
// engine at the client's bone transforms, so fail-through is exact: the full values are what the
// cache was trained to approximate. Sections as a PMSC model (pmsc_io.h) plus skeleton.* and
// animspace.* (the engine), sequence.frames (the engine's output, F/2 × 3N) and
// sequence.bone_transforms (the poses it was evaluated at, F/2 × 48); the training options are
// stored, so it can be retrained. Errors: the fitter's and trainer's (none expected).
Result<container::ModelContainer> make_demo_pmsc_engine_container(int frames = kDemoFrames);
// The same from an arm-animspace container already made (make_demo_animation_space_container):
// write_demo_repository fits the engine once for both models.
Result<container::ModelContainer> make_demo_pmsc_engine_container(
    const container::ModelContainer& animation_space_demo);

inline constexpr std::string_view kDemoIlluminationModelName = "cornell";

// The seeds' second application (Meyer & Anderson 2007 §3.2): the Cornell box's one-bounce
// indirect illumination for the 12 × 12 grid of point lights under its ceiling, as a PMSC model of
// RGB radiance that carries its illumination engine (illumination::train_illumination). Sized for
// a demo that must start in moments (measured in docs/BENCHMARKS.md): a few thousand surface
// points and a short gather; the bench and `animspace train-illumination` use the papers' sizes.
// 128 rays a point (issue #55 item 14): with 16 the relit walls were visibly mottled — each point's
// noise is the same under every light (its ray directions are fixed), so the subspace keeps it as
// blotches; 8× the rays is √8 ≈ 2.8× less of it, for about 2 s more of `make run`'s start.
struct DemoIlluminationOptions {
  int points = 3000;
  int samples = 128;
  int lights_x = 12;
  int lights_z = 12;
};
Result<container::ModelContainer> make_demo_illumination_container(const DemoIlluminationOptions& options = {});

// Writes `cornell` (version 1) into `repository`. Kept apart from write_demo_repository, which the
// tests call often: only the daemon's and the CLI's demo repositories carry it.
Status write_demo_illumination(const std::filesystem::path& repository, const DemoIlluminationOptions& options = {});

inline constexpr std::string_view kDemoSmoothModelName = "arm-smooth";

// The thesis's two systems on the demo arm: arm-animspace subdivided once in animation space
// (Merry 2007 §4.2, Loop: P' = P S, so it poses exactly as the posed arm subdivided, with limit
// normals), carrying a texture atlas balanced across its poses (ch. 5: charts under the L2,2
// metric of its stored P, flattened minimising L2 stretch across the poses, packed). Errors: the
// subdivision's and the atlas's (none expected).
Result<container::ModelContainer> make_demo_smooth_container(const container::ModelContainer& animation_space_demo);

// Writes `arm-smooth` (version 1), made from the `arm-animspace` already in `repository`. Kept apart
// from write_demo_repository, like the illumination model, for the tests that call that often.
Status write_demo_smooth(const std::filesystem::path& repository);

inline constexpr std::string_view kDemoArticulatedModelName = "arm-articulated";

// The arm as an articulated PMSC model (issue #51, pmsc/articulated.h): the arm-pmsc training
// frames and options, but a basis built on the arm's skinning — bone transforms as coordinates,
// then principal components of what the skinning leaves (the biceps, the elbow's kept volume) —
// so that a pose past every training pose stays inside it. Training options are stored, so the
// server can retrain it. Errors: the trainer's (none expected).
Result<container::ModelContainer> make_demo_articulated_container(int frames = kDemoFrames);

// Writes `arm-articulated` (version 1). Kept apart from write_demo_repository like the models
// above: its skinning decomposition is the longest step of the arm's models.
Status write_demo_articulated(const std::filesystem::path& repository);

// What `animspaced` serves without --model-repository and `animspace demo-repository` writes:
// write_demo_repository, write_demo_illumination, write_demo_smooth and write_demo_articulated,
// each a step of `progress`'s stage "demo models" (the whole takes seconds).
Status write_bundled_demo(const std::filesystem::path& repository, const ProgressCallback& progress = {});

// The path of the demo model's file inside `repository`.
std::filesystem::path demo_model_path(const std::filesystem::path& repository);

// Writes the demo models (default options, kDemoFrames frames) — arm, arm-pmsc, arm-cross-pmsc,
// arm-animspace and arm-pmsc-engine, version 1 each — creating directories as needed; files are
// replaced atomically. Errors: kIo naming the directory that could not be created, the container
// writer's error, or a model builder's.
Status write_demo_repository(const std::filesystem::path& repository);

}  // namespace animspace::demo
