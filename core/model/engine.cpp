#include "core/model/engine.h"

#include <utility>

namespace animspace::model {
namespace {

class AnimationSpaceEngine final : public Engine {
 public:
  explicit AnimationSpaceEngine(std::shared_ptr<const animation_space::AnimationSpaceModel> model)
      : model_(std::move(model)) {}
  Input input() const override { return Input::kSkeletonPose; }
  void frame(const EngineInput& input, Eigen::VectorXf& out) const override {
    PointMatrix posed;
    animation_space::evaluate(*model_, input.globals, posed);
    out = Eigen::Map<const Eigen::VectorXf>(posed.data(), posed.size());
  }
  void points(const EngineInput& input, const std::vector<int>& points, Eigen::VectorXf& out) const override {
    PointMatrix posed;
    animation_space::evaluate_vertices(*model_, input.globals, points, posed);
    out = Eigen::Map<const Eigen::VectorXf>(posed.data(), posed.size());
  }

 private:
  std::shared_ptr<const animation_space::AnimationSpaceModel> model_;
};

class IlluminationEngine final : public Engine {
 public:
  explicit IlluminationEngine(std::shared_ptr<const illumination::ServedIllumination> served)
      : served_(std::move(served)) {}
  Input input() const override { return Input::kLightSet; }
  void frame(const EngineInput& input, Eigen::VectorXf& out) const override {
    served_->full(input.lights, out);  // the gather and the surface filter (issue #38 item 1)
  }
  void points(const EngineInput& input, const std::vector<int>& points, Eigen::VectorXf& out) const override {
    served_->keys(input.lights, points, out);  // key_samples rays: no neighbours to filter with
  }

 private:
  std::shared_ptr<const illumination::ServedIllumination> served_;
};

}  // namespace

std::string_view input_name(Engine::Input input) {
  return input == Engine::Input::kSkeletonPose ? "skeleton_pose" : "light_set";
}

std::shared_ptr<const Engine> make_animation_space_engine(
    std::shared_ptr<const animation_space::AnimationSpaceModel> model) {
  return std::make_shared<AnimationSpaceEngine>(std::move(model));
}

std::shared_ptr<const Engine> make_illumination_engine(std::shared_ptr<const illumination::ServedIllumination> served) {
  return std::make_shared<IlluminationEngine>(std::move(served));
}

}  // namespace animspace::model
