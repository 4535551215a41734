// Storing a trained PMSC model in the model container, and loading it back for serving.
//
// Sections (see docs/FORMATS.md): pmsc.mean (1 × N·D f32), pmsc.basis (N·D × M f32),
// pmsc.key_points (K × 1 i32), pmsc.key_mean (1 × K·D f64), pmsc.key_basis (K·D × M f64),
// pmsc.epsilon (1 × 2 f64: ε_min, ε_max), pmsc.point_regions (N × 1 i32, optional) and
// pmsc.key_regions (K × 1 i32, optional); metadata pmsc.channels, pmsc.cross, pmsc.aligned,
// pmsc.control_point_count, pmsc.region_count. The projection is not stored: it is recomputed
// (and its conditioning re-checked) at load, so there is one source of truth.
#pragma once

#include <string>

#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/train.h"

namespace animspace::pmsc {

// Writes the model's sections and metadata; sets metadata "kind" to pmsc or cross_pmsc.
void store(const PmscModel& model, container::ModelContainer& out);

// Reads, validates and prepares a model. Errors name `source` and the section.
Result<PmscModel> load(const container::ModelContainer& in, const std::string& source);

// A complete, servable model container: the output mesh (`mesh.V`: N × 3 positions of the output
// points; faces optional), the training frames (kept so that retraining can start from them, SPEC
// "train each night"), the model, and the training report as metadata.
// `training_frames` is F × N·D output frames; `control_frames` (cross-PMSC only) F × N_c·D.
container::ModelContainer make_container(const TriangleMesh& mesh, const FrameMatrix& training_frames,
                                         const FrameMatrix* control_frames, const PmscModel& model,
                                         const TrainingReport& report, const std::string& description);

}  // namespace animspace::pmsc
