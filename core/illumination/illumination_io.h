// The illumination engine a PMSC model of colours carries (SPEC "Fail-through"): the surface and
// the gather settings, stored beside the model's sections so that the daemon can compute the
// full indirect illumination itself for a light a request sends, and so that a thumbnail can draw
// the scene the colours belong to. Shapes in docs/FORMATS.md.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/illumination/gather.h"
#include "core/illumination/surface_filter.h"
#include "core/illumination/surface.h"

namespace animspace::illumination {

namespace sections {
// The sample points are the shared mesh.rest_points (N×3) and mesh.faces.
inline constexpr const char* kNormals = "illumination.normals";                  // N×3 float32
inline constexpr const char* kAlbedo = "illumination.albedo";                    // N×3 float32
inline constexpr const char* kTrainingLights = "illumination.training_lights";  // F×6 float64: position, intensity
inline constexpr const char* kView = "illumination.view";  // 1×10 float64: eye, target, up, vertical fov (rad); optional
}  // namespace sections

// A camera the scene is meant to be seen from (thumbnails draw it when a request names none).
struct SceneView {
  Eigen::Vector3d eye = Eigen::Vector3d(0, 0, 1);
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();
  double vertical_fov_rad = 0.7;
};

// The Cornell box's published camera (Cornell "Cornell Box Data": eye (278, 273, −800) mm
// looking along +z, 35 mm lens over a 25 mm film: a 39.3° field of view), in metres.
SceneView cornell_view();

// What a model's illumination engine is built from.
struct IlluminationSetup {
  SurfaceMesh surface;
  GatherOptions gather;
  // The lights the model was trained on, in training order (its frames' order).
  std::vector<PointLight> training_lights;
  // Which values the model's points are: "indirect" (one-bounce L_i, the papers' quantity).
  std::string quantity = "indirect";
  std::optional<SceneView> view;
  // Issue #38 item 1: the filter the training frames went through (the full calculation applies
  // it too), and the rays per key point, unfiltered, when the server gathers the keys itself (0:
  // gather_keys's default, the filtered values at the keys).
  SurfaceFilterOptions filter;
  int key_samples = 0;
};

// Writes the setup's sections and metadata (illumination.samples, illumination.seed,
// illumination.quantity; illumination.filter_neighbours, .filter_min_normal_cosine,
// .filter_linear and .key_samples only when set, so files without them read as before) into `out`, replacing
// mesh.rest_points and mesh.faces.
void attach_illumination(container::ModelContainer& out, const IlluminationSetup& setup);

bool has_illumination(const container::ModelContainer& in);

// A model's illumination engine made ready to serve: the scene built for ray tracing, the gather
// it was trained with (fail-through must compute the same function the subspace learned), the
// training lights, the view, and the radiance scale its tolerances were stated in.
struct ServedIllumination {
  std::shared_ptr<const IlluminationEngine> engine;
  GatherOptions gather;
  // Issue #38 item 1: the key points' gather (gather with key_samples rays) and the surface
  // filter precomputed once for every full frame (off for files without it).
  GatherOptions key_gather;
  std::shared_ptr<const SurfaceFilter> filter;
  std::vector<PointLight> training_lights;
  std::optional<SceneView> view;
  double radiance_scale = 0;  // metadata illumination.radiance_scale; 0 when absent
  // The intensity a request's light takes when it names none: the first training light's.
  Eigen::Vector3d default_intensity() const {
    return training_lights.empty() ? Eigen::Vector3d::Ones() : training_lights.front().intensity;
  }
  // The full calculation the subspace learned: the gather at every point, then the filter.
  void full(const std::vector<PointLight>& lights, Eigen::VectorXf& out) const;
  // The key points' values: gather_keys with this model's gather, filter and key_samples.
  void keys(const std::vector<PointLight>& lights, const std::vector<int>& points, Eigen::VectorXf& out) const;
};

// The values at a model's key points for `lights` (3·|points|), as the subspace expects them
// (issue #38 item 1). key_samples > 0: the gather at `points` alone with that many rays (no
// filter: the noise at a few hundred points is cheap to remove with rays). Otherwise, with the
// filter on: the gather (gather's rays) at every point the key points' filters read, then the
// filter at the key points — the full calculation's values there bit for bit. Filter off: the
// gather at `points`.
void gather_keys(const IlluminationEngine& engine, const GatherOptions& gather, const SurfaceFilter* filter,
                 int key_samples, const std::vector<PointLight>& lights, const std::vector<int>& points,
                 Eigen::VectorXf& out);

// load_illumination, then the engine built. Errors: load_illumination's; the engine's, naming
// `source`.
Result<ServedIllumination> load_served_illumination(const container::ModelContainer& in, const std::string& source);

// Errors: kInvalidArgument naming `source` and the section or key (shapes against
// mesh.rest_points, check_surface, samples ≥ 1, key_samples ≥ 1, the filter's options, an unknown
// quantity).
Result<IlluminationSetup> load_illumination(const container::ModelContainer& in, const std::string& source);

}  // namespace animspace::illumination
