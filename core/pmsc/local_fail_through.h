// Local fail-through: the full calculation only where the subspace estimate fails.
//
// Both seeds leave this as future work (Meyer & Anderson 2006 §7, 2007 §5): the soft cache of
// 2007 §2.3–2.4 judges the whole pose by one RMS key-point error, so a blend or miss needs the
// full values f of every point. Here each region (regions.h: points with similar motion
// signatures) is judged by the RMS error of its own key points, with the same eqs. 9–11:
//   α_r = decide(region_errors[r], region_thresholds(model, r)).alpha
// and each point takes the α of the regions it belongs to, through soft memberships w_ir
// (a partition of unity, at most kMaxRegionsPerPoint regions per point):
//   α_i = Σ_r w_ir α_r,    out_i = α_i f_i + (1 − α_i) f̂_i      (eq. 11 per point)
// Only the points with α_i > 0 need f. Memberships ramp linearly across region borders, so α
// has no seam where two regions meet (the 2007 §2.4 argument for the blend zone, in space rather
// than in time): a hard partition would switch a vertex from f to f̂ between two neighbours.
//
// The whole-pose verdict (status, α, e_key of evaluate_cached) is unchanged: local fail-through
// is what a caller may do instead of the whole-pose blend on a blend or miss. A hit stays a hit.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

// A point belongs to at most this many regions (three regions meet at a junction of borders).
inline constexpr int kMaxRegionsPerPoint = 3;
// Width of the ramp between two regions, as a fraction of the distance between their centroids
// in signature space: 0.25 blends the quarter of the way between two centroids that lies
// around their bisector; each centroid itself stays at weight 1 for any band ≤ 1.
inline constexpr double kRegionBorderBand = 0.25;

// Soft memberships (N × R, float64; rows sum to 1, at most kMaxRegionsPerPoint non-zero per
// row) of N points in R regions. `signatures` is N × S (motion_signatures in regions.h);
// `point_regions` (N, values in [0, R)) is the hard partition whose region means are the
// centroids c_r. For each pair of regions (r, s) the signed distance of a signature x to their
// bisector, in units of the band b_rs = border_band·‖c_r − c_s‖, is
//   t_rs(x) = (‖x − c_s‖² − ‖x − c_r‖²) / (2·border_band·‖c_r − c_s‖²),
// linear in x; u_r = clamp(½ + min_s t_rs, 0, 1) is 1 deep inside r and falls to 0 across the
// band. The largest kMaxRegionsPerPoint u_r, normalised, are the weights. Two regions: exactly
// a linear ramp of width b_rs centred on the bisector (u_r + u_s = 1 there). border_band in (0, 1].
Eigen::MatrixXd soft_region_weights(const Eigen::MatrixXd& signatures, const std::vector<int>& point_regions,
                                    int region_count, double border_band = kRegionBorderBand);

// The hard memberships w_ir = [r = point_regions[i]] (N × R): what a model without soft
// memberships (written before pmsc.region_weights) uses.
Eigen::MatrixXd hard_region_weights(const std::vector<int>& point_regions, int region_count);

// Checks model.region_weights: empty, or point_count × region_count with entries in [0, 1],
// rows summing to 1 (within 1e-6) and at most kMaxRegionsPerPoint non-zero entries per row.
// Error: kInvalidArgument naming the member, the row and the offending value.
Status check_region_weights(const PmscModel& model);

// The points of one pose that need the full calculation, and their weights.
struct LocalFailThrough {
  std::vector<int> full_points;                   // sorted point indices with α_i > 0
  std::vector<double> full_point_blend_weights;   // α_i ∈ (0, 1] of each, same order
};

// α_i for every point from a pose's error estimate and region errors (PoseEstimate::
// error_estimate and region_errors, R values; `checked`: the pose came with check values). A
// model without regions has one region, the whole pose: every point takes the whole-pose α. So
// does a pose without check values of a model with check points: its regions are calibrated for
// estimates that include check points. A cross-PMSC model has no full calculation: the result is
// empty.
LocalFailThrough local_fail_through(const PmscModel& model, double error_estimate,
                                    const std::vector<double>& region_errors, bool checked = false);
inline LocalFailThrough local_fail_through(const PmscModel& model, const PoseEstimate& estimate) {
  return local_fail_through(model, estimate.error_estimate, estimate.region_errors, estimate.checked);
}

// Error (kInvalidArgument) naming the first point of `needed.full_points` missing from
// `full_points` (sorted) and its blend weight: partial full values must cover every point the
// soft cache cannot answer alone.
Status check_covers(const LocalFailThrough& needed, const std::vector<int>& full_points);

// out = f̂ with each point i of `local.full_points` replaced by α_i f_i + (1 − α_i) f̂_i (eq. 11
// per point; f_i itself where α_i = 1, as eq. 9 does for a miss). `full_points` (sorted, a
// superset of local.full_points, asserted) names the points whose D values `full_values` holds
// (|full_points|·D, point-major); values of points outside local.full_points are not read.
// estimate and out: N·D (may alias).
void blend_partial(const PmscModel& model, const LocalFailThrough& local,
                   const Eigen::Ref<const Eigen::VectorXf>& estimate, const std::vector<int>& full_points,
                   const Eigen::Ref<const Eigen::VectorXf>& full_values, Eigen::Ref<Eigen::VectorXf> out);

// The full calculation of some points — a posing engine the caller holds, as FullCalculation but
// for the listed points only (sorted indices): writes |points|·D values in that order and returns
// true, or returns false when it cannot compute this pose.
using PartialFullCalculation = std::function<bool(const std::vector<int>& points, Eigen::VectorXf& values)>;

// Local fail-through for one pose: evaluate_cached's verdict (status, α, e_key unchanged); on a
// blend or miss of a non-cross model, `local` lists the points that need f and out.points is
// blend_partial of f̂ with full values for them — given (`full_values` for the sorted
// `full_points`, which must cover local.full_points) or, when none are given, computed by
// `full_calculation` (may be empty) for local.full_points only, kept in out.computed_full_values
// (|local.full_points|·D). Without f, out.points is f̂ and out.full_evaluation_needed is set —
// unless no point needs f (every region within tolerance), when f̂ is the answer. A hit leaves
// `local` empty and never calls `full_calculation`.
// Errors: kInvalidArgument from check_covers when `full_points` misses a point that needs f.
Status evaluate_cached_local(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                             const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                             const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local);
// The same for a pose sent with its check values (C·D; size 0: none).
Status evaluate_cached_local(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                             const Eigen::Ref<const Eigen::VectorXf>& check_values,
                             const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                             const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local);

// The same on a pose whose f̂ is already in `points` (N·D, from reconstruct; the answer is written
// over it in place): the verdict of `estimate`, then the local blend as above. Fills every member
// of `out` but `points`.
Status finish_cached_local(const PmscModel& model, const PoseEstimate& estimate, Eigen::Ref<Eigen::VectorXf> points,
                           const std::vector<int>& full_points, const Eigen::VectorXf* full_values,
                           const PartialFullCalculation& full_calculation, CachedPose& out, LocalFailThrough& local);

// Whether a pose's regions are judged each against its own thresholds: the model has regions,
// and they were calibrated for this estimate (with check values, or a model without check
// points). Otherwise every region takes the whole pose's verdict.
bool regions_judged_alone(const PmscModel& model, bool checked);

// Each region's verdict for a judged pose (judge / finish_cached filled `pose`), by the rule
// above: what a client sees per region and what local fail-through acts on.
std::vector<CacheStatus> region_statuses(const PmscModel& model, const CachedPose& pose);

// A whole frame (N·D) from a partial one, for retraining: the given points' full values; at the
// other key points their key values (they are the full calculation at those points); elsewhere
// the model's estimate f̂ for `key_values`, which the soft cache judged within tolerance there.
// `full_points` sorted and in range, `full_values` |full_points|·D (asserted). Not cross-PMSC.
Eigen::VectorXf complete_partial_frame(const PmscModel& model, const Eigen::Ref<const Eigen::VectorXf>& key_values,
                                       const std::vector<int>& full_points,
                                       const Eigen::Ref<const Eigen::VectorXf>& full_values);

}  // namespace animspace::pmsc
