// Calibrating the soft cache's thresholds so that a HIT means something stated in advance
// (Meyer & Anderson 2006 §5, 2007 §2.3: e_key is compared with ε; the papers pick ε by hand).
//
// The estimate. e_key, the RMS key-point residual (eq. 8), is kept as the error estimate: on the
// captured sequences we have it ranks unseen frames by their true max point error as well as any
// alternative we measured (leave-one-key-out residuals through the hat matrix, the worst
// region's RMS; docs/BENCHMARKS.md "pmsc"), and it costs nothing. What was wrong was the
// calibration: one worst-case ratio from a few folds is dominated by a single outlier.
//
// The calibration (split-conformal, class-conditional, in its cross-validated form). Held-out
// training frames give samples (e_key, true max point error e_max) in two families: folds that drop
// every k-th frame (poses between training poses) and folds that drop whole blocks of consecutive
// frames (motion the rest never saw). What a HIT must not be is a pose over the tolerance, so the
// rule looks at those: in each family, the held-out frames with e_max > tolerance ("bad") have
// e_key values b_(1) ≤ … ≤ b_(m); for a false-hit rate δ, r = ⌊δ (m + 1)⌋ of them may lie at or
// below ε_min, so ε_min = b_(r) (r ≥ 1), or just below b_(1) (r = 0: m < 1/δ − 1 samples promise
// less than δ, and the rule takes the strictest value they allow). ε_min is the smaller of the two
// families' values and never above the tolerance (e_key ≤ e_max always: e_key > tolerance is bad).
// Meaning: for a pose over the tolerance that is exchangeable with one family's bad frames,
// P(called HIT) ≤ r / (m + 1) ≤ δ — "at most δ of poses over the tolerance are called HIT".
//
// When no held-out frame is over the tolerance there is nothing to condition on; the rule falls
// back to the error ratio: scores s = e_max / e_key, q the ⌈(1 − δ)(n + 1)⌉-th smallest of the n
// scores (the largest when δ < 1/(n + 1)), ε_min = tolerance / q — "P(e_max > q · e_key) ≤ δ".
// Either way ε_max = blend_zone_ratio · ε_min, and error_ratio = tolerance / ε_min is reported.
//
// Per region (local fail-through): the same rule on each region's RMS key error and the max
// error over that region's points gives each region its own thresholds.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/pmsc/soft_cache.h"

namespace animspace::pmsc {

// Held-out frames with e_key below this fraction of the tolerance are reproduced to rounding:
// their score is noise over noise and is not used.
inline constexpr double kCalibrationNoiseFraction = 1e-4;

// The samples of a calibration: one row per held-out frame.
struct CalibrationSamples {
  // Whether each sample came from a block fold (1) or an interleaved one (0).
  std::vector<char> from_block_fold;
  Eigen::VectorXd key_point_errors;  // n, e_key of each held-out frame
  Eigen::VectorXd max_errors;        // n, its true max point error
  // n × R (R = regions, 0 without regions): each region's RMS key error and the max point error
  // over the region's points.
  Eigen::MatrixXd region_key_point_errors;
  Eigen::MatrixXd region_max_errors;
  long size() const { return key_point_errors.size(); }
};

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
                                        const std::vector<char>& from_block_fold, double tolerance,
                                        double false_hit_rate);

// What a choice of δ gives on the calibration samples themselves (cross-validated: each sample
// came from a model that did not train on its frame).
struct OperatingPoint {
  double false_hit_rate = 0;   // δ asked for
  double error_ratio = 0;      // tolerance / ε_min
  double epsilon_min = 0;
  double hit_rate = 0;         // samples with e_key ≤ ε_min
  double miss_recall = 1;      // samples over tolerance with e_key > ε_min, of those over tolerance (1 if none)
  long over_tolerance = 0;     // samples with e_max > tolerance
  double worst_hit_error = 0;  // largest e_max among samples called HIT, over the tolerance
};

OperatingPoint operating_point(const CalibrationSamples& samples, double false_hit_rate, double tolerance);

// The δ an operator is offered by default (train-pmsc, the bench): 0.005 … 0.2.
std::vector<double> default_false_hit_rates();

}  // namespace animspace::pmsc
