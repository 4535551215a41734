// A model file made ready to serve: the one sequence the daemon's registry, the offline tools'
// checks and the container fuzzer all run on a container, so that what is fuzzed is what loads.
#pragma once

#include <memory>
#include <optional>
#include <vector>
#include <string>

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/illumination/illumination_io.h"
#include "core/lod/levels.h"
#include "core/model/model_info.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::model {

struct Servable {
  ModelInfo info;
  // The soft-cache runtime of a PMSC or cross-PMSC model.
  std::optional<pmsc::PmscModel> pmsc;
  // The skinning model of an animation-space model, or the posing engine a PMSC model carries
  // for server fail-through (SPEC "Fail-through"), with its LOD levels (Merry 2007 §7.3; level 0
  // is the model itself) and the sphere eq. 7.2 measures depth to.
  std::optional<animation_space::AnimationSpaceModel> animation_space;
  std::optional<lod::LodLevels> lod_levels;
  geometry::BoundingSphere bounding_sphere;
  // The illumination engine a PMSC model of RGB radiance carries for server fail-through.
  std::optional<illumination::ServedIllumination> illumination;
};

// describe → pmsc::load and/or animation_space::load → lod::load_levels →
// lod::model_bounding_sphere, or illumination::load_illumination → IlluminationEngine::create. Errors: the first refusal, naming `source`.
Result<Servable> load_servable(const container::ModelContainer& container, const std::string& source);

}  // namespace animspace::model
