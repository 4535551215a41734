// The illumination engine a PMSC model of colours carries (SPEC "Fail-through"): the surface and
// the gather settings, stored beside the model's sections so that the daemon can compute the
// full indirect illumination itself for a light a request sends, and so that a thumbnail can draw
// the scene the colours belong to. Shapes in docs/FORMATS.md.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/illumination/gather.h"
#include "core/illumination/surface.h"

namespace animspace::illumination {

namespace sections {
// The sample points are the shared mesh.rest_points (N×3) and mesh.faces.
inline constexpr const char* kNormals = "illumination.normals";                  // N×3 float32
inline constexpr const char* kAlbedo = "illumination.albedo";                    // N×3 float32
inline constexpr const char* kTrainingLights = "illumination.training_lights";  // F×6 float64: position, intensity
}  // namespace sections

// What a model's illumination engine is built from.
struct IlluminationSetup {
  SurfaceMesh surface;
  GatherOptions gather;
  // The lights the model was trained on, in training order (its frames' order).
  std::vector<PointLight> training_lights;
  // Which values the model's points are: "indirect" (one-bounce L_i, the papers' quantity).
  std::string quantity = "indirect";
};

// Writes the setup's sections and metadata (illumination.samples, illumination.seed,
// illumination.quantity) into `out`, replacing mesh.rest_points and mesh.faces.
void attach_illumination(container::ModelContainer& out, const IlluminationSetup& setup);

bool has_illumination(const container::ModelContainer& in);

// Errors: kInvalidArgument naming `source` and the section or key (shapes against
// mesh.rest_points, check_surface, samples ≥ 1, an unknown quantity).
Result<IlluminationSetup> load_illumination(const container::ModelContainer& in, const std::string& source);

}  // namespace animspace::illumination
