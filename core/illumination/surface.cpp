#include "core/illumination/surface.h"

// Placeholder until the implementation lands (helper branch).
namespace animspace::illumination {
Status check_surface(const SurfaceMesh&, const std::string& name) {
  return make_error(ErrorCode::kUnimplemented, name + ": not built yet");
}
SurfaceMesh cornell_box(const CornellBoxOptions&) { return {}; }
Box cornell_room() { return {Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()}; }
std::vector<Eigen::Vector3d> light_grid(const Box&, const LightGrid&) { return {}; }
}  // namespace animspace::illumination
