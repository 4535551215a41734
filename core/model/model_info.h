// What a model version is and what it can do, read from its container once at load time.
//
// The daemon answers DescribeModel from this, and refuses a container whose sections disagree
// with each other (a frame matrix whose width is not 3·N, faces indexing past N, …) before it
// ever serves it.
#pragma once

#include <string>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"

namespace animspace::model {

using container::ModelKind;

// How a blend or miss obtains the full values (SPEC "Fail-through").
enum class FailThrough { kNone, kServer, kClient, kImpossible };

// The full calculation a PMSC model with server fail-through carries: an animation-space model
// posed at a request's skeleton, or the illumination engine gathering for a request's lights.
enum class ServerEngine { kNone, kAnimationSpace, kIllumination };

struct ModelInfo {
  ModelKind kind = ModelKind::kMeshSequence;
  std::string description;
  int point_count = 0;    // N
  int channel_count = 3;  // D
  int face_count = 0;
  int bone_count = 0;
  int frame_count = 0;
  int key_point_count = 0;
  int basis_size = 0;
  int lod_level_count = 0;
  float epsilon_min = 0;
  float epsilon_max = 0;
  FailThrough fail_through = FailThrough::kNone;
  ServerEngine server_engine = ServerEngine::kNone;
  // PMSC, from the loaded runtime (load_servable; describe reads shapes only and leaves them 0):
  // C check points (issue #35), the calibration's false-hit rate δ and over-tolerance samples,
  // whether they back δ, and the sentence an operator reads (pmsc::calibration_statement).
  int check_point_count = 0;
  double false_hit_rate = 0;
  long calibration_bad_samples = 0;
  // Of those, held-out frames over the tolerance themselves (the rest extrapolated; issue #52).
  long calibration_real_bad_samples = 0;
  bool calibration_guarantee_holds = false;
  std::string calibration_statement;
  bool relative_tolerance = false;  // pmsc::PmscModel::relative_tolerance (issue #38)
  // pmsc::PmscModel::subspace_kind, bone_count and residual_components (issue #51), from the
  // loaded runtime like the members above; "" for a model that is not PMSC.
  std::string subspace_kind;
  int subspace_bone_count = 0;
  int residual_components = 0;
};

// Reads and cross-checks the sections every kind shares. Errors: kInvalidArgument (or the
// container's own error) naming `source`, the section and expected vs actual shape.
Result<ModelInfo> describe(const container::ModelContainer& model, const std::string& source);

}  // namespace animspace::model
