// The server's full calculation of a PMSC model's frames (SPEC "Fail-through"; Meyer & Anderson
// 2007 §2.4 runtime step 5): one interface for every posing engine a model file can carry, built
// once when the model loads (load_servable), so that a caller asks "which input does this model's
// engine take" once instead of testing which runtime is present.
//
//   animation space  — a skeleton pose (G_j per joint) → the posed vertices (Merry 2007 eq. 3.1)
//   illumination     — a light set → one-bounce radiance at the surface samples (2007 §3.2)
//
// Both evaluate point by point (a vertex alone; a deterministic per-point gather), so a point
// computed alone equals its value in the whole frame: local fail-through computes only the points
// that need it, and the illumination engine gathers a pose's key and check values itself.
#pragma once

#include <memory>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/illumination/illumination_io.h"

namespace animspace::model {

// What an engine computes a frame from; only the member of the engine's input() is read.
struct EngineInput {
  animation_space::TransformList globals;        // kSkeletonPose: G_j for every joint
  std::vector<illumination::PointLight> lights;  // kLightSet: the frame's lights
};

class Engine {
 public:
  enum class Input { kSkeletonPose, kLightSet };

  virtual ~Engine() = default;
  virtual Input input() const = 0;
  // The whole frame: N·D values, point-major.
  virtual void frame(const EngineInput& input, Eigen::VectorXf& out) const = 0;
  // The points `points` only: |points|·D values in that order, each equal to its value in frame().
  virtual void points(const EngineInput& input, const std::vector<int>& points, Eigen::VectorXf& out) const = 0;
};

// The input's name as a request spells it: "skeleton_pose" or "light_set".
std::string_view input_name(Engine::Input input);

// Engines over runtimes the caller keeps alive (the servable that holds both).
std::shared_ptr<const Engine> make_animation_space_engine(
    std::shared_ptr<const animation_space::AnimationSpaceModel> model);
std::shared_ptr<const Engine> make_illumination_engine(std::shared_ptr<const illumination::ServedIllumination> served);

}  // namespace animspace::model
