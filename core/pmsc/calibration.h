// Calibrating the soft cache's thresholds so that a HIT means something stated in advance
// (Meyer & Anderson 2006 §5, 2007 §2.3: an error estimate is compared with ε; the papers pick ε
// by hand).
//
// The estimate (issue #35). e_key, the RMS key-point residual (eq. 8), cannot see an error where
// there is no key point: on unseen motion a pose can be far over the tolerance with every key
// point well reproduced. Check points are a second, small set of points the projection never
// uses; the client poses them like key points and e_check = max ‖f_c − f̂_c‖ over them is the
// true error there. The verdict compares e = max(w·e_key, e_check) with ε (a pose without check
// values: e_key alone, against thresholds calibrated for e_key alone). w is chosen by the rule
// below; docs/BENCHMARKS.md "pmsc" compares the estimators measured before choosing.
//
// The samples. Held-out training frames give (e_key, e_check, true max point error e_max) from
// three fold families, each fold retraining the subspace without its frames: every k-th frame
// (poses between training poses), blocks of consecutive frames at three lengths (motion the rest
// never saw), and sparse folds that train on half of an interleaved fold's frames (a model that
// has seen less). Several hundred samples, most of them under the tolerance.
//
// The rule (issue #35: enough bad examples). A HIT must not be a pose over the tolerance, and
// the held-out frames over it are few (1–11 on the captures we measured: too few to state 2%).
// So every held-out residual r = f − f̂ is also extrapolated along itself to just over the
// tolerance: the pose f̂ + s·r with s = tolerance / e_max. Its key values are f̂_key + s·r_key, and
// r_key is orthogonal to the range of A_key (it is a least-squares residual), so its projection
// and f̂ are unchanged and its errors scale exactly: e' = s·e, e_max' = tolerance⁺. These m
// samples are the bad examples: ε_min is the r-th smallest of their estimates e_(1) ≤ … ≤ e_(m),
// r = ⌊δ (m + 1)⌋ (split-conformal, class-conditional). A bad pose whose residual is like one of
// them — at any distance past the tolerance, since its estimate only grows with s — is then
// called HIT with probability ≤ δ. Equivalently ε_min = tolerance / q, q the ⌈(1 − δ)(m + 1)⌉-th
// smallest ratio e_max / e: the conformal error ratio on every held-out frame. With r = 0 (m <
// 1/δ − 1) no rate can be stated: ε_min sits just below every bad sample and the model says so
// (calibration_statement). Rigid alignment re-fits the motion of the extrapolated keys, so for
// aligned models the scaling is first order, not exact.
//
// w is the weight of the candidates w₀·2^k (k = −4 … 4, w₀ the median e_check / e_key of the
// samples) and 0 (check points alone) whose calibrated ε calls HIT the most held-out samples under
// the tolerance, counted over the whole offered range of δ (default_false_hit_rates): the
// guarantee holds for each candidate, and the choice only trades hits. Ties go to the candidate
// nearest w₀, check points alone last: a weight that ignores e_key would pass a pose whose keys are
// off wherever the check points happen to be right. One weight for every δ (issue #55 item 9):
// chosen afresh for each δ, the operating curve's rows thresholded different estimators, and ε_min
// and the hits could fall as δ rose (crane --align: ε_min 0.0205 at δ = 0.005, 0.0119 at 0.01).
// With one estimator, a larger δ admits a later rank of the same sorted bad samples, so ε_min and
// the hits never fall; `calibrate --false-hit-rate` moves along that curve and keeps the weight.
//
// Per region (local fail-through): the same rule on each region's estimate (its key points' RMS
// error, its check points' worst) and the max error over that region's points.
//
// Issue #22's rule — ε_min the r-th smallest e_key of the held-out frames that are over the
// tolerance on their own, per fold family, with the error-ratio rule when there are none — is
// kept (calibrate_epsilon_min) as the baseline the bench measures against.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/pmsc/soft_cache.h"

namespace animspace::pmsc {

// The error estimate of a pose sent with check points (issue #35): the worse of the key residual,
// weighted, and the check residual. e_check is the true error at C points, so it never exceeds
// the pose's max point error; w·e_key stands for the error where neither key nor check point is.
inline double combined_error_estimate(double key_weight, double key_point_error, double check_point_error) {
  return key_weight * key_point_error > check_point_error ? key_weight * key_point_error : check_point_error;
}

// Held-out frames with e_key below this fraction of the tolerance are reproduced to rounding:
// their score is noise over noise and is not used.
inline constexpr double kCalibrationNoiseFraction = 1e-4;

// The fold family a held-out sample came from.
inline constexpr char kInterleavedFold = 0;
inline constexpr char kBlockFold = 1;
inline constexpr char kSparseFold = 2;

// The samples of a calibration: one row per held-out frame.
struct CalibrationSamples {
  // The fold family of each sample (kInterleavedFold, kBlockFold, kSparseFold); models of pmsc
  // format 2 hold only the first two.
  std::vector<char> fold_family;
  Eigen::VectorXd key_point_errors;    // n, e_key of each held-out frame
  // n, its worst key point's residual (PoseEstimate::key_point_max_error); empty in models
  // calibrated before issue #52.
  Eigen::VectorXd key_point_max_errors;
  Eigen::VectorXd check_point_errors;  // n, its e_check; empty for a model without check points
  Eigen::VectorXd max_errors;          // n, its true max point error
  // n × R (R = regions, 0 without regions): each region's RMS key error, its check points' worst
  // error (empty without check points) and the max point error over the region's points.
  Eigen::MatrixXd region_key_point_errors;
  Eigen::MatrixXd region_check_point_errors;
  Eigen::MatrixXd region_max_errors;
  long size() const { return key_point_errors.size(); }
  bool checked() const { return check_point_errors.size() > 0; }
  // The error estimate of each sample: max(w·e_key, e_check) when checked and `use_check`, else e_key.
  Eigen::VectorXd error_estimates(double key_weight, bool use_check = true) const;
  // The same for region r.
  Eigen::VectorXd region_error_estimates(long region, double key_weight, bool use_check = true) const;
};

// The rule of the header (issue #35) for one set of samples: ε_min from the held-out residuals
// extrapolated to just over the tolerance. Samples with e_max below kCalibrationNoiseFraction ·
// tolerance (reproduced to rounding) have no direction to extrapolate and are skipped.
struct ExtrapolatedEpsilon {
  double epsilon_min = 0;
  long bad_samples = 0;     // m, the extrapolated samples ε rests on
  long over_tolerance = 0;  // of the held-out frames, those over the tolerance on their own
};
ExtrapolatedEpsilon calibrate_extrapolated(const Eigen::Ref<const Eigen::VectorXd>& error_estimates,
                                           const Eigen::Ref<const Eigen::VectorXd>& max_errors, double tolerance,
                                           double false_hit_rate);

// Whether m bad samples can state a false-hit rate δ: ⌊δ (m + 1)⌋ ≥ 1.
bool guarantee_holds(long bad_samples, double false_hit_rate);

// The weight w of e_key in the estimate (the header's rule), the same for every δ. 1 for samples
// without check points.
double choose_key_weight(const CalibrationSamples& samples, double tolerance);

// The conformal error ratio q for false-hit rate δ ∈ (0, 1) from paired samples (e_key, e_max);
// samples with e_key < noise_floor are skipped. 1 when no sample is usable (e_key never exceeds
// the largest key error, and so is a lower bound of e_max only at the keys: the least a ratio
// can be). Sets *usable to the number of samples used when given.
double conformal_error_ratio(const Eigen::Ref<const Eigen::VectorXd>& key_point_errors,
                             const Eigen::Ref<const Eigen::VectorXd>& max_errors, double false_hit_rate,
                             double noise_floor, long* usable = nullptr);

// The rule of the header for one set of samples (the whole pose, or one region's columns).
struct CalibratedEpsilon {
  double epsilon_min = 0;
  long over_tolerance = 0;    // held-out frames over the tolerance (both families)
  bool ratio_fallback = false;  // none was: the error-ratio rule decided
};
CalibratedEpsilon calibrate_epsilon_min(const Eigen::Ref<const Eigen::VectorXd>& key_point_errors,
                                        const Eigen::Ref<const Eigen::VectorXd>& max_errors,
                                        const std::vector<char>& fold_family, double tolerance,
                                        double false_hit_rate);

// What a choice of δ gives on the calibration samples themselves (cross-validated: each sample
// came from a model that did not train on its frame).
struct OperatingPoint {
  double false_hit_rate = 0;   // δ asked for
  long bad_samples = 0;        // the extrapolated bad samples ε rests on
  double error_ratio = 0;      // tolerance / ε_min
  double epsilon_min = 0;
  double hit_rate = 0;         // samples with e_key ≤ ε_min
  double miss_recall = 1;      // samples over tolerance with e_key > ε_min, of those over tolerance (1 if none)
  long over_tolerance = 0;     // samples with e_max > tolerance
  double worst_hit_error = 0;  // largest e_max among samples called HIT, over the tolerance
};

// With the rule of the header on the estimates max(w·e_key, e_check) (e_key alone when the samples
// have no check points): the ε_min that false-hit rate gives, and what it does on the samples. With
// w the model's own key_weight this is the model's curve, the same weight for every δ.
OperatingPoint operating_point(const CalibrationSamples& samples, double key_weight, double false_hit_rate,
                               double tolerance);

// The δ an operator is offered by default (train-pmsc, the bench): 0.005 … 0.2.
std::vector<double> default_false_hit_rates();

}  // namespace animspace::pmsc
