#include "core/illumination/gather.h"

// Placeholder until the implementation lands (helper branch).
namespace animspace::illumination {
Status check_gather_options(const GatherOptions&) { return make_error(ErrorCode::kUnimplemented, "gather"); }
Status check_lights(const std::vector<PointLight>&, const std::string& name, int) {
  return make_error(ErrorCode::kUnimplemented, name);
}
struct IlluminationEngine::Embree {};
IlluminationEngine::IlluminationEngine(SurfaceMesh surface) : surface_(std::move(surface)) {}
IlluminationEngine::~IlluminationEngine() = default;
Result<std::unique_ptr<IlluminationEngine>> IlluminationEngine::create(SurfaceMesh) {
  return make_error(ErrorCode::kUnimplemented, "illumination engine");
}
void IlluminationEngine::direct(const std::vector<PointLight>&, const std::vector<int>&, Eigen::VectorXf&) const {}
void IlluminationEngine::indirect(const std::vector<PointLight>&, const GatherOptions&, const std::vector<int>&,
                                  Eigen::VectorXf&) const {}
std::vector<int> IlluminationEngine::all_points() const { return {}; }
}  // namespace animspace::illumination
