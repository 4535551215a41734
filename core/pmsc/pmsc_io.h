// Storing a trained PMSC model in the model container, and loading it back for serving.
//
// Sections (see docs/FORMATS.md): pmsc.mean (1 × N·D f32), pmsc.basis (N·D × M f32),
// pmsc.key_points (K × 1 i32), pmsc.key_mean (1 × K·D f64), pmsc.key_basis (K·D × M f64),
// pmsc.epsilon (1 × 2 f64: ε_min, ε_max), pmsc.point_regions (N × 1 i32, optional) and
// pmsc.key_regions (K × 1 i32, optional), pmsc.region_weights (N × R f64, optional: soft
// memberships for local fail-through; without it the regions are hard); metadata pmsc.channels,
// pmsc.cross, pmsc.aligned, pmsc.control_point_count, pmsc.region_count. From pmsc format 2
// (metadata pmsc.format_version, absent in format 1) also the ε calibration (calibration.h):
// pmsc.calibration_samples (n × (3 + 2R) f64: fold family (0 interleaved, 1 block), e_key, max
// error, then R region key errors and R region max errors of each held-out frame),
// pmsc.region_epsilon (R × 2 f64) and metadata pmsc.calibration.false_hit_rate, .error_ratio,
// .block_frames, .over_tolerance. A format 1 model loads with the ε it was written with and no
// samples. From format 3 (issue #35) also the check points: pmsc.check_points (C × 1 i32),
// pmsc.check_regions (C × 1 i32, with regions), pmsc.key_only_epsilon (1 × 2 f64), metadata
// pmsc.key_weight; the calibration's fold family may be 2 (sparse), and
// pmsc.calibration_check_errors (n × (1 + R) f64: e_check, then each region's) and metadata
// pmsc.calibration.bad_samples join it. A format 2 model loads without check points. The projection is not stored: it is recomputed
// (and its conditioning re-checked) at load, so there is one source of truth.
//
// Beside the model a container keeps what retraining needs ("train each night, better
// tomorrow", core/pmsc/retrain.h): the training frames (sequence.frames), the training options
// (metadata pmsc.options.<name>) and, optionally, a posing engine — an animation-space model of
// the same N points (skeleton.*, animspace.*; core/animspace/animspace_io.h) with which the
// server computes the full values itself on a blend or miss (fail-through "server").
#pragma once

#include <functional>
#include <string>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/container/model_container.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/train.h"

namespace animspace::pmsc {

// The pmsc sections' format (docs/FORMATS.md): 1 before the stored calibration, 2 with it, 3 with
// check points and the extrapolated calibration (issue #35).
inline constexpr int kFormatVersion = 3;
inline constexpr const char* kFormatVersionKey = "pmsc.format_version";
inline constexpr const char* kFalseHitRateKey = "pmsc.calibration.false_hit_rate";
inline constexpr const char* kErrorRatioKey = "pmsc.calibration.error_ratio";
inline constexpr const char* kBlockFramesKey = "pmsc.calibration.block_frames";
inline constexpr const char* kOverToleranceKey = "pmsc.calibration.over_tolerance";
inline constexpr const char* kCalibrationSamplesSection = "pmsc.calibration_samples";
inline constexpr const char* kRegionEpsilonSection = "pmsc.region_epsilon";
inline constexpr const char* kBadSamplesKey = "pmsc.calibration.bad_samples";
inline constexpr const char* kCalibrationCheckErrorsSection = "pmsc.calibration_check_errors";
inline constexpr const char* kCheckPointsSection = "pmsc.check_points";
inline constexpr const char* kCheckRegionsSection = "pmsc.check_regions";
inline constexpr const char* kKeyOnlyEpsilonSection = "pmsc.key_only_epsilon";
inline constexpr const char* kKeyWeightKey = "pmsc.key_weight";
// Issue #52: the verdict's estimator ("key_rms" when absent: every model before it) and each
// calibration sample's worst key error (n × 1; absent before it).
inline constexpr const char* kEstimatorKey = "pmsc.estimator";
inline constexpr const char* kCalibrationKeyMaxErrorsSection = "pmsc.calibration_key_max_errors";
// The section of PmscModel::region_weights (read and written only here, hence not in sections.h).
inline constexpr const char* kRegionWeightsSection = "pmsc.region_weights";

// Writes the model's sections and metadata; sets metadata "kind" to pmsc or cross_pmsc.
void store(const PmscModel& model, container::ModelContainer& out);

// Reads, validates and prepares a model. Errors name `source` and the section.
Result<PmscModel> load(const container::ModelContainer& in, const std::string& source);

// A complete, servable model container: the output mesh (`mesh.V`: N × 3 positions of the output
// points; faces optional), the training frames (kept so that retraining can start from them, SPEC
// "train each night"), the model, and the training report as metadata.
// `training_frames` is F × N·D output frames, moved into the container (FrameMatrix&& set_matrix: a
// caller that lets go of its frames holds them once); `control_frames` (cross-PMSC only) F × N_c·D.
container::ModelContainer make_container(const TriangleMesh& mesh, FrameMatrix training_frames,
                                         const FrameMatrix* control_frames, const PmscModel& model,
                                         const TrainingReport& report, const std::string& description);

// The training report as metadata: pmsc.training_frames, pmsc.max_training_error,
// pmsc.condition_number, pmsc.error_ratio, pmsc.training_seconds (make_container writes it).
void store_training_report(const TrainingReport& report, container::ModelContainer& out);

// Prefix of the persisted training options' metadata keys.
inline constexpr const char* kOptionsPrefix = "pmsc.options.";

// Writes every TrainingOptions field that retraining needs as metadata "pmsc.options.<field>":
// channels, error_bound, basis_size, max_basis, max_basis_fraction, block_size, max_key_points,
// fiducial_points (comma-separated indices, empty for none), grid_cells, remove_rigid_motion
// ("1"/"0"), error_tolerance, calibration_folds, blend_zone_ratio, region_count, false_hit_rate and
// calibration_block_frames (the last two optional on reading: older models lack them). Doubles are
// written in the shortest form that reads back to the same bits. `positions` (explicit grid
// positions) is not stored: a retrained model that uses grid seeds places them on the mean of
// its own training frames, the default — so the grid may move a little when misses join.
void store_training_options(const TrainingOptions& options, container::ModelContainer& out);

// Reads the options stored by store_training_options (`positions` left empty).
// Errors: kFailedPrecondition "<source>: model was trained before training options were stored
// (no pmsc.options.*); retrain it from the CLI" when no pmsc.options.* key exists;
// kInvalidArgument naming the key when one is missing, unparsable (not exactly a decimal of the
// field's type) or unknown (written by a newer trainer: retraining without it would differ).
Result<TrainingOptions> load_training_options(const container::ModelContainer& in, const std::string& source);

// Posing engine. Stores `engine`'s skeleton (skeleton.*) and influences (animspace.*) in a pmsc
// container `out`, so that the server can compute the full values f = Σ_j G_j p_j (Merry 2007
// eq. 3.1) for a blend or miss itself: model::describe then reports fail_through kServer and the
// engine's bone_count, and animation_space::load(out) returns the engine. The container's own
// mesh.rest_points (the PMSC reference) is kept; mesh.faces is taken from the engine only when
// the container has none. Metrics and LOD levels of the engine are not stored.
// Errors: kInvalidArgument when the engine is invalid (validate), its vertex count differs from
// the container's point count N (mesh.rest_points), pmsc.channels is not 3 (an engine makes
// positions), or sequence.bone_transforms exists with a width other than 16·B; kFailedPrecondition
// when `out` is not a (non-cross) pmsc container — cross-PMSC outputs have no full calculation.
Status attach_posing_engine(const animation_space::AnimationSpaceModel& engine, container::ModelContainer& out);

// Whether `in` carries a posing engine (skeleton.parents and animspace.influence_offsets);
// model::describe checks the sections' shapes, animation_space::load their values.
bool has_posing_engine(const container::ModelContainer& in);

// Copies every section of `in` whose name `keep` accepts into `out` as it is (a section left on
// disk stays there; a section of the same name in `out` is replaced). Metadata is not copied.
void copy_sections(const container::ModelContainer& in, const std::function<bool(const std::string&)>& keep,
                   container::ModelContainer& out);

}  // namespace animspace::pmsc
