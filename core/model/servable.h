// A model file made ready to serve: the one sequence the daemon's registry, the offline tools'
// checks and the container fuzzer all run on a container, so that what is fuzzed is what loads.
#pragma once

#include <array>
#include <memory>
#include <span>
#include <vector>
#include <string>

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/illumination/illumination_io.h"
#include "core/lod/levels.h"
#include "core/model/engine.h"
#include "core/model/model_info.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/subspace.h"

namespace animspace::model {

// Immutable once loaded: its runtimes are shared, so that the registry's LoadedModel is this
// servable (not a copy of it field by field) and a call in flight keeps what it uses alive.
struct Servable {
  ModelInfo info;
  // The soft-cache runtime of a PMSC or cross-PMSC model (null for other kinds).
  std::shared_ptr<const pmsc::PmscModel> pmsc;
  // Its runtime for the subspace's kind, built once here: what every pose goes through
  // (estimate, reconstruct, finish; core/pmsc/subspace.h).
  std::shared_ptr<const pmsc::Subspace> subspace;
  // Its mean and basis named exactly (pmsc::basis_checksum), for clients that reconstruct
  // answers sent as coordinates; 0 for other kinds.
  uint64_t basis_checksum = 0;
  // And named so that it cannot be forged (pmsc::basis_sha256): what a client's cached copy is
  // checked against (issue #54 item 8); empty for other kinds.
  std::string basis_sha256;
  // The same subspace as GetBasis sends it in float16 (pmsc::float16_basis, issue #53): its
  // digest and largest rounding error; `float16_refusal` says why it cannot be sent so (a value
  // beyond ±65504), and the digest is then empty.
  pmsc::Float16Basis float16_basis;
  std::string float16_refusal;
  // An articulated model's basis in GetBasis's SKINNED layout (pmsc::skinned_basis, issue #51
  // item 4), built once here; null for other models, and for one whose basis does not expand back
  // from it (the dense layout alone is then offered). Only the slots are held: the mean and the
  // residual columns are sent from the model's own `mean` and last `basis` columns (parts()).
  struct SkinnedLayout {
    int bone_count = 0;        // B
    int influences = 0;        // K
    std::vector<float> slots;  // pmsc::skinned_slot_values
    std::string sha256;        // of the float32 values as sent
    pmsc::Float16Basis float16;
    std::string float16_refusal;
    // The values in GetBasis's order, as three runs: the mean, the slots, the residual columns.
    std::array<std::span<const float>, 3> parts(const pmsc::PmscModel& model) const;
  };
  std::shared_ptr<const SkinnedLayout> skinned;
  std::string skinned_refusal;  // why `skinned` is null, for a PMSC model
  // The skinning model of an animation-space model, or the posing engine a PMSC model carries
  // for server fail-through (SPEC "Fail-through"), with its LOD levels (Merry 2007 §7.3; level 0
  // is the model itself) and the sphere eq. 7.2 measures depth to (null otherwise).
  std::shared_ptr<const animation_space::AnimationSpaceModel> animation_space;
  std::shared_ptr<const lod::LodLevels> lod_levels;
  geometry::BoundingSphere bounding_sphere;
  // The illumination engine a PMSC model of RGB radiance carries for server fail-through.
  std::shared_ptr<const illumination::ServedIllumination> illumination;
  // The full calculation of a PMSC model with a server engine (either runtime above, behind one
  // interface: engine.h); null when fail-through is the client's or impossible.
  std::shared_ptr<const Engine> engine;
};

// describe → pmsc::load and/or animation_space::load → lod::load_levels →
// lod::model_bounding_sphere, or illumination::load_illumination → IlluminationEngine::create. Errors: the first refusal, naming `source`.
Result<Servable> load_servable(const container::ModelContainer& container, const std::string& source);

}  // namespace animspace::model
