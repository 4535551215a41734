// Check points (issue #35): where to measure the error the key points cannot see.
//
// The key points are chosen to reconstruct the training frames (2007 §2.2); they say little about
// where a pose the training never saw goes wrong. The check points are chosen from the held-out
// residuals of the calibration folds (calibration.h), which are exactly such errors: each held-out
// sample i has a per-point error e_ij and a max e_max,i, and a check set J covers it by
//   c_i(J) = max over j ∈ J of e_ij / e_max,i    (1 when J holds the sample's worst point).
// First one point per region, in the order of the regions' summed normalised error (the point of
// the region with the largest Σ_i e_ij / e_max,i), so that every region of the body is measured
// while the count allows; then greedily the point that adds the most coverage, Σ_i max(0,
// e_ij / e_max,i − c_i) — the facility-location objective, submodular, so greedy is within 1 − 1/e
// of the best set of its size. Key points are never check points: their error is e_key's.
#pragma once

#include <vector>

#include <Eigen/Core>

namespace animspace::pmsc {

// The default number of check points for K key points: ⌈kCheckPointFraction · K⌉ (issue #35: at
// most a quarter more points for the client to pose).
inline constexpr double kCheckPointFraction = 0.2;

// `sample_errors`: the per-point errors of held-out samples, one N-vector each, as the calibration
// folds produce them (no n × N copy of them is made: at 186k points × 2,500 samples one is
// 1.9 GB, issue #53); `samples`: the ones to judge by, indices into `sample_errors` and
// `max_errors` (their maxima); samples with max below `noise_floor` are skipped. `point_regions`
// (N, or empty) and `region_count` (0 without regions). Returns min(count, N − K) point indices
// in selection order.
std::vector<int> select_check_points(const std::vector<Eigen::VectorXf>& sample_errors, const std::vector<long>& samples,
                                     const Eigen::VectorXd& max_errors, const std::vector<int>& key_points,
                                     const std::vector<int>& point_regions, int region_count, int count,
                                     double noise_floor);
// The same for n × N errors, every row a sample (`max_errors`: n).
std::vector<int> select_check_points(const Eigen::MatrixXf& point_errors, const Eigen::VectorXd& max_errors,
                                     const std::vector<int>& key_points, const std::vector<int>& point_regions,
                                     int region_count, int count, double noise_floor);

}  // namespace animspace::pmsc
