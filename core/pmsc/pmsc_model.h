// A trained PMSC / KPSA subspace and its runtime (Meyer & Anderson 2007 §2, eqs. 1, 2, 8).
//
//   f̂ = mean + A p,   p = argmin ‖f_key − mean_key − A_key p‖
//
// A (the basis) comes from PCA of the initial training matrix only (2007 §2.2, last paragraph).
// The least-squares projection P = A_key⁺ is precomputed once (libigl style: *_precompute then
// evaluate), guarded for conditioning: keys must supply at least as many equations as there are
// basis vectors, and when A_key is ill-conditioned a Tikhonov term is added and reported.
//
// Cross-PMSC (2007 §3.1): the key points belong to a control point set and the output is a
// different point set; the joint subspace is trained on stacked (control, output) frames, and
// only the key rows of the control part (key_mean, key_basis) and the output part (mean, basis)
// are kept. No full calculation exists for the output, so fail-through is impossible.
//
// Rigid alignment (beyond the papers): captured whole-body data moves across the room, which a
// linear subspace spends most of its dimensions on. With `aligned`, training frames were aligned
// to a reference before PCA; at run time the rigid transform is estimated from the key points
// alone (alternating Procrustes and projection), the subspace runs in the aligned frame, and the
// estimate is moved back.
#pragma once

#include <functional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/geometry/rigid_fit.h"
#include "core/pmsc/calibration.h"
#include "core/pmsc/soft_cache.h"

namespace animspace::pmsc {

// What the basis A is (issue #51). Both kinds share eq. 2 — p from the key rows by least squares —
// and f̂ = mean + A p; they differ in what A's columns are, and so in how a server reconstructs
// f̂ fast (each kind's runtime, subspace.h):
//   kLinear       principal components of the training frames (2007 §2.1);
//   kArticulated  a linear blend skinning model's Jacobian — 12 columns per bone, the bone's
//                 affine transform about its rest centre (articulated.h) — then principal
//                 components of what the skinning leaves in the training frames. A limb turned
//                 further than in any training frame is still a combination of these columns,
//                 which a position PCA cannot reach.
enum class SubspaceKind : int { kLinear = 0, kArticulated = 1 };
// "linear", "articulated": the name in model files, on the command line and on the wire.
const char* subspace_kind_name(SubspaceKind kind);

// What the whole pose's verdict measures of the key points (issue #52):
//   kKeyRms      e_key, their RMS residual (2007 eq. 8) — every model before issue #52;
//   kWorstPoint  the worst key point's residual, max_k ‖f_k − f̂_k‖: an error under a few of K
//                keys moves the RMS by only √(few/K) of itself, so a local error a key does see
//                (a limb turned further on a new shot, a bulge) went unnoticed in the RMS.
// Either is weighted and joined with e_check (calibration.h, combined_error_estimate) and
// calibrated the same way. Region errors stay RMS over each region's keys.
enum class ErrorEstimator : int { kKeyRms = 0, kWorstPoint = 1 };
// "key_rms", "worst_point": the name in model files and reports.
const char* error_estimator_name(ErrorEstimator estimator);

struct PmscModel {
  int channel_count = 3;             // D
  int point_count = 0;          // N, output points
  int control_point_count = 0;  // points key indices refer to (== N unless cross)
  bool cross = false;
  bool aligned = false;         // requires channels == 3
  SubspaceKind subspace_kind = SubspaceKind::kLinear;
  ErrorEstimator estimator = ErrorEstimator::kKeyRms;
  // Articulated models: p = (bone transforms, 12 per bone, then residual coefficients).
  int bone_count = 0;            // B
  int residual_components = 0;   // r; M = 12·B + r

  Eigen::VectorXf mean;                 // N·D, output mean, point-major (x0 y0 z0 x1 …)
  Eigen::MatrixXf basis;                // N·D × M, output basis A (column-major for the GEMV)
  std::vector<int> key_points;          // K indices into the control points, fiducials first
  Eigen::VectorXd key_mean;             // K·D, mean at the key rows
  Eigen::MatrixXd key_basis;            // K·D × M, A_key
  SoftCacheThresholds epsilon;
  // Local fail-through: region of each output point (0 … region_count−1) and of each key point.
  int region_count = 0;
  std::vector<int> point_regions;  // N (empty when region_count == 0)
  std::vector<int> key_regions;    // K
  // Soft memberships w_ir of each output point in each region (N × region_count, rows sum to 1,
  // at most 3 regions per point; local_fail_through.h), so that per-point blend weights have no
  // seam at region borders. Empty: the hard regions, w_ir = [r = point_regions[i]] (models
  // written before pmsc.region_weights).
  Eigen::MatrixXd region_weights;
  // Soft-cache thresholds of each region's key-point error (region_errors), calibrated like
  // `epsilon` on each region's own points; empty: every region uses `epsilon` (models written
  // before per-region calibration). Read through region_thresholds().
  std::vector<SoftCacheThresholds> region_epsilon;

  // Check points (issue #35): C control points, none of them a key point, that the projection
  // never uses. The client poses them like key points; their worst residual e_check is a direct
  // measurement of f − f̂ where the key points are blind, and joins e_key in the error estimate
  // the verdict compares with ε (calibration.h):
  //   e = max(key_weight · e_key, e_check)          (pose sent with check values)
  //   e = e_key, compared with key_only_epsilon      (pose sent without: older clients)
  // Empty (cross-PMSC models and models written before issue #35): e = e_key against `epsilon`.
  std::vector<int> check_points;      // C indices into the control points, in the order sent
  std::vector<int> check_regions;     // C, region of each check point (empty without regions)
  double key_weight = 1;              // w ≥ 0 of e_key in the estimate
  SoftCacheThresholds key_only_epsilon;  // ε for poses without check values (models with check points)

  // A tolerance relative to each pose (issue #38: a HIT must mean the same for a dim and a bright
  // light). Every error the soft cache measures — e_key, e_check, the region errors, and the
  // calibration samples' max point errors — is divided by the pose's own scale
  //   S = RMS over the output points of ‖f̂_i‖ = sqrt(pᵀ (AᵀA) p / N),
  // so ε and the training tolerance are fractions of S. Such a model is linear (mean 0: training
  // makes the frames' mean a basis direction), so keys s·f_key give s·f̂ and s·S, and every verdict
  // is the same at any intensity. Not with `aligned` (a position has no intensity). False: errors
  // in model units (every model before issue #38).
  bool relative_tolerance = false;

  // How `epsilon` and `region_epsilon` were calibrated (calibration.h). No samples: a model
  // written before issue #22, whose ε is the worst held-out ratio's and cannot be recalibrated.
  struct Calibration {
    double false_hit_rate = 0;  // δ
    double error_ratio = 0;     // tolerance / ε_min
    long over_tolerance = 0;    // held-out frames over the tolerance (0: the error-ratio fallback)
    int block_frames = 0;       // frames per held-out block (the shortest block family)
    // Over-tolerance samples ε_min rests on (issue #35: held-out frames over the tolerance and
    // every held-out residual extrapolated to just over it); the guarantee holds when
    // ⌊δ (bad_samples + 1)⌋ ≥ 1 (calibration_guarantee_holds). 0: a model calibrated before.
    long bad_samples = 0;
    CalibrationSamples samples;
  } calibration;

  // Precomputed by prepare_projection():
  Eigen::MatrixXd projection;   // M × K·D, P with p = P (f_key − key_mean)
  double condition_number = 0;  // σ_max / σ_min of A_key
  double regularization = 0;    // Tikhonov λ added (0 when well conditioned)
  // Aligned models only: an orthonormal basis U (K·D × r) of the range of A_key, and Σ_k U_kᵀ
  // (r × 3), the constant translation part of Uᵀ G in the rigid Gauss–Newton step.
  Eigen::MatrixXd key_range;
  Eigen::MatrixXd key_range_translation;
  // The check rows of mean and basis (C·D and C·D × M, in the aligned frame when aligned).
  Eigen::VectorXd check_mean;
  Eigen::MatrixXd check_basis;
  // Relative-tolerance models only: AᵀA (M × M), so that S costs M² and not a reconstruction.
  Eigen::MatrixXd basis_gram;
  int basis_size() const { return static_cast<int>(basis.cols()); }
  int key_point_count() const { return static_cast<int>(key_points.size()); }
  int check_point_count() const { return static_cast<int>(check_points.size()); }
};

// Largest condition number of A_key accepted without regularisation.
inline constexpr double kMaxConditionNumber = 1e6;
// Refusal bound on ‖A‖_F·‖P‖_F, the amplification from key values to points (prepare_projection).
inline constexpr double kMaxAmplification = 1e20;

// Least-squares projection P (M × K·D) for key rows `key_basis` (K·D × M) through the SVD, with
// Tikhonov regularisation λ = (σ_max/max_condition)² when σ_max/σ_min > max_condition; also the
// minimum-norm solution when K·D < M. Reports σ_max/σ_min and λ.
// `range` (optional) receives the left singular vectors of A_key with σ > 0.
Eigen::MatrixXd least_squares_projection(const Eigen::MatrixXd& key_basis, double max_condition,
                                         double* condition_number, double* regularization,
                                         Eigen::MatrixXd* range = nullptr);

// Checks the shapes and values of every member (except the precomputed ones) and computes the
// projection. Errors: kInvalidArgument naming the member and the expected vs actual shape;
// kFailedPrecondition when K·D < M (fewer key equations than basis vectors).
Status prepare_projection(PmscModel& model);

struct PoseEstimate {
  Eigen::VectorXf points;            // N·D estimate f̂ (world frame when aligned)
  Eigen::VectorXd coordinates;       // M, subspace coordinates p
  double key_point_error = 0;        // e_key = rms(f_key − f̂_key), eq. 8
  // The worst key point's residual, max_k ‖f_k − f̂_k‖ (issue #52): a local error under a few of
  // K keys moves the RMS by only √(few/K) of itself.
  double key_point_max_error = 0;
  // e_check = max over check points of ‖f_c − f̂_c‖ (0 when `checked` is false).
  double check_point_error = 0;
  bool checked = false;              // the pose came with check values
  // What the verdict compares with verdict_thresholds(): max(w·k, e_check) when checked, else k,
  // with k the model's estimator's key term (e_key, or key_point_max_error).
  double error_estimate = 0;
  // Per region, the same estimate over the region's key and check points (empty without regions).
  std::vector<double> region_errors;
  // S, the pose's scale every error above is a fraction of (relative_tolerance; +Inf errors when
  // S is 0: nothing to be relative to, a miss); 1 for a model with errors in model units.
  double scale = 1;
  geometry::RigidTransform alignment;          // aligned frame → world (identity unless aligned)
};

// Evaluation is two steps, so that a server can evaluate poses that arrive together as one
// matrix product (issue #25, dynamic batching):
//   estimate_coordinates   eq. 2 for one pose: p, e_key, region errors, the rigid alignment —
//                          always one pose at a time, so a pose's verdict never depends on what
//                          else it was evaluated with;
//   reconstruct            eq. 1, f̂ = mean + A p, for any number of poses at once.
// Products run through the active kernel (core/common/kernels.h). These free functions work on
// any kind through the dense basis, the reference every client reconstructs by; a server goes
// through the model's Subspace (subspace.h), whose kind may reconstruct faster.

// Eq. 2 for one pose. `key_values` holds K·D values in key order. The model must be prepared.
// Values are assumed finite (the caller validates input; asserted in debug builds). Leaves
// out.points empty.
void estimate_coordinates(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                          PoseEstimate& out);
// The same with the pose's check values (C·D in check_points order; size 0: none, as above).
// With check values p is unchanged (the projection never uses them) and e_check, the error
// estimate and the region errors include them.
void estimate_coordinates(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                          const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out);

// The thresholds a pose's error estimate is compared with: `epsilon` when it was checked or the
// model has no check points, else key_only_epsilon.
inline const SoftCacheThresholds& verdict_thresholds(const PmscModel& model, const PoseEstimate& estimate) {
  return estimate.checked || model.check_points.empty() ? model.epsilon : model.key_only_epsilon;
}

// S of a relative-tolerance model's pose with coordinates p: sqrt(pᵀ (AᵀA) p / N), the RMS point
// norm of f̂ = A p without reconstructing it. The model must be prepared and relative.
double pose_scale(const PmscModel& model, const Eigen::VectorXd& coordinates);

// Rows of the basis per block of a batched reconstruction: block × B floats of products stay in
// cache (256 KB) while the mean is added on the way to each pose's destination.
inline constexpr long kReconstructionBlockValues = 65536;

// Eq. 1 for the poses `estimates` (from estimate_coordinates): f̂_b = mean + A p_b, moved to the
// world for aligned models, written to destinations[b] (N·D floats each; may be a message's
// buffer). The basis is read once for the whole batch. A pose reconstructed alone or in any batch
// differs only by float rounding, at most
//   reconstruction_rounding_bound(M) · (|mean_i| + Σ_j |A_ij p_j|)
// in value i (both orders of the M + 1 float additions are within γ_{M+1} of the exact sum;
// an aligned model's rotation then moves each point's error, not its size).
void reconstruct(const PmscModel& model, std::span<const PoseEstimate* const> estimates,
                 std::span<float* const> destinations);

inline double reconstruction_rounding_bound(long basis_size) {
  const double u = 0x1p-24;  // float's unit roundoff
  const double gamma = static_cast<double>(basis_size + 2) * u;
  return 2 * gamma / (1 - gamma);
}

// Both steps for one pose: out.points is f̂.
void evaluate(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values, PoseEstimate& out);

// A batch: `key_values` is K·D × B (one pose per column); `points` becomes N·D × B and
// `key_point_errors` B. One reconstruction for the batch.
void evaluate_batch(const PmscModel& model, const Eigen::Ref<const Eigen::MatrixXf>& key_values,
                    Eigen::MatrixXf& points, Eigen::VectorXd& key_point_errors);

// The soft-cached answer for one pose (Meyer & Anderson 2007 §2.4, runtime step 4): what a caller
// returns to a client. Always carries status, e_key and α.
struct CachedPose {
  Eigen::VectorXf points;  // N·D: f̂ (hit), α f + (1 − α) f̂ (blend), f (miss) — or f̂ when no f
  CacheStatus status = CacheStatus::kHit;
  double key_point_error = 0;
  double key_point_max_error = 0;  // as PoseEstimate
  double check_point_error = 0;  // as PoseEstimate
  bool checked = false;
  double error_estimate = 0;     // what the verdict compared with verdict_thresholds
  double scale = 1;              // S (PoseEstimate::scale): the errors' unit in a relative model
  double alpha = 0;
  // Blend or miss, but no full values were given: `points` is the estimate and the caller must
  // supply f (or accept f̂). Never set for cross-PMSC models, where no full calculation exists.
  bool full_evaluation_needed = false;
  std::vector<double> region_errors;
  // f as the full calculation computed it for this pose (fail-through), else empty: the
  // example a miss log keeps for retraining (2007 §2.4).
  Eigen::VectorXf computed_full_values;
};

// Evaluates one pose through the soft cache. `full_values` (N·D, optional) is the expensive
// calculation for this pose when the caller has it; it is only read on a blend or miss.
void evaluate_cached(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::VectorXf* full_values, CachedPose& out);

// The full calculation of one pose — a posing engine the caller holds (SPEC "Fail-through":
// the server's animation-space model, posed at the request's skeleton). Writes f (N·D values,
// the model's point-major layout) and returns true, or returns false when it cannot compute this
// pose. Called at most once, and only when the soft cache cannot answer alone.
using FullCalculation = std::function<bool(Eigen::VectorXf& full_values)>;

// Fail-through (Meyer & Anderson 2007 §2.4, runtime steps 4–5): evaluate_cached, and when the
// verdict is a blend or a miss and the caller sent no full values, run `full_calculation` (may
// be empty: none) and blend with its f exactly as with values the caller sent (eqs. 9–11);
// out.computed_full_values keeps that f. Without f the result is evaluate_cached's
// (full_evaluation_needed set). Never calls it for a hit or a cross-PMSC model.
void evaluate_cached(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::VectorXf* full_values, const FullCalculation& full_calculation,
                     CachedPose& out);
// The same for a pose sent with its check values (C·D; size 0: none).
void evaluate_cached(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                     const Eigen::Ref<const Eigen::VectorXf>& check_values, const Eigen::VectorXf* full_values,
                     const FullCalculation& full_calculation, CachedPose& out);

// The verdict of `estimate` (eqs. 8–11) into `out`: status, α and the errors, with
// full_evaluation_needed false and `points` untouched — all an answer sent as coordinates needs.
// Returns whether the answer needs the full values f: a blend or miss of a model that has them
// (not cross-PMSC).
bool judge(const PmscModel& model, const PoseEstimate& estimate, CachedPose& out);

// The soft cache on a pose whose f̂ is already in `points` (N·D, from reconstruct): the verdict
// and α of `estimate`, fail-through and blend as evaluate_cached does, with the answer written
// over f̂ in place. Fills every member of `out` but `points`.
void finish_cached(const PmscModel& model, const PoseEstimate& estimate, Eigen::Ref<Eigen::VectorXf> points,
                   const Eigen::VectorXf* full_values, const FullCalculation& full_calculation, CachedPose& out);

// Full values belong to the pose their key values came from: at each key point the full frame
// must repeat the key values (a client that sends an unrelated "full pose" — zeros, the previous
// frame — would otherwise teach the next retrain a wrong example; issue #21). Rounding and
// posing engines that are not bit-reproducible are allowed a difference of
//   |f − f_key| ≤ kKeyConsistencyRelative · max(|f|, |f_key|) + kKeyConsistencyAbsolute · ε_min
// per value: a relative part for float arithmetic, an absolute part far below what the soft cache
// can notice (e_key is compared with ε_min).
inline constexpr double kKeyConsistencyRelative = 1e-5;
inline constexpr double kKeyConsistencyAbsolute = 1e-3;

// Checks that `full_values` (control_point_count·D, not cross-PMSC) repeat `key_values` (K·D) at
// the key points. Error: kInvalidArgument naming the first key point that differs, its point
// index, and both values.
Status check_full_values_at_keys(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                 const Eigen::Ref<const Eigen::VectorXf>& full_values);

// The same check for partial full values (local fail-through): `full_points` (sorted, in
// [0, control_point_count)) names the points whose D values `full_values` holds
// (|full_points|·D); the key points among them are checked, the others cannot be.
Status check_full_values_at_keys(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                 const std::vector<int>& full_points,
                                 const Eigen::Ref<const Eigen::VectorXf>& full_values);

// The same at the check points (issue #35): the check values a pose was sent with (C·D; size 0:
// none, nothing to check) must be repeated by its full values — whole, or partial for the sorted
// `full_points` (the check points among them). Error: kInvalidArgument naming the first check point
// that differs, its point index, and both values.
Status check_full_values_at_checks(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& check_values,
                                   const Eigen::Ref<const Eigen::VectorXf>& full_values);
Status check_full_values_at_checks(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& check_values,
                                   const std::vector<int>& full_points,
                                   const Eigen::Ref<const Eigen::VectorXf>& full_values);

// The thresholds region r's key-point error is compared with (local fail-through).
inline const SoftCacheThresholds& region_thresholds(const PmscModel& model, int region) {
  return model.region_epsilon.empty() ? model.epsilon : model.region_epsilon[static_cast<size_t>(region)];
}

// model.calibration's samples with the whole pose's key term as the model's estimator measures it
// (key_point_max_errors for kWorstPoint, e_key otherwise): what ε, the key weight and the operating
// curve are computed on. The samples must hold that term (apply_calibration checks it).
CalibrationSamples estimator_samples(const PmscModel& model);

// Sets ε (and each region's ε when the samples have regions) from model.calibration's samples
// and false_hit_rate (calibration.h). Errors: kInvalidArgument for a δ outside (0, 1), a
// non-positive tolerance, blend_zone_ratio < 1, or samples whose region columns differ from
// region_count; kFailedPrecondition when the model has no samples (trained before issue #22).
Status apply_calibration(PmscModel& model, double tolerance, double blend_zone_ratio);

// Gathers the key rows (K·D) of a full control frame (control_point_count·D values).
Eigen::VectorXf gather_key_values(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& control_frame);
// Gathers the check rows (C·D) of a full control frame (empty for a model without check points).
Eigen::VectorXf gather_check_values(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& control_frame);

// Whether the calibration can state its false-hit rate: ⌊δ (bad_samples + 1)⌋ ≥ 1, i.e. at
// least 1/δ − 1 over-tolerance samples. False for models calibrated before issue #35.
bool calibration_guarantee_holds(const PmscModel& model);
// One sentence an operator reads (describe, train-pmsc, ModelVersion): what a HIT means for this
// model, or why nothing is guaranteed.
std::string calibration_statement(const PmscModel& model);

// The fraction of `control_frames` (F × control_point_count·D, one frame per row) whose key
// values the soft cache answers as a HIT (0 for F = 0): what an operator sees change when ε
// is recalibrated.
double hit_rate(const PmscModel& model, const FrameMatrix& control_frames);

}  // namespace animspace::pmsc
