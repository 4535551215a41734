// The calibration samples' per-point errors as training keeps them for the check points
// (check_points.h), in a quarter of the bytes of a float copy per sample plus the copy the
// selection made of them (issue #53 item 2: at 186k points × 2,500 held-out samples each was
// 1.9 GB, beside 1.1 GB of frames).
//
// The selection reads each error relative to its sample's largest, u_ij = e_ij / e_max,i ∈ [0, 1];
// held as 16-bit fixed point rounded down, every u_ij is within 2⁻¹⁶ below the exact ratio, so an
// e_check read back from it (e_max,i · u_ij) never exceeds the true error. That is the safe side
// for the calibration: a sample whose error the check points see as smaller makes ε smaller.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace animspace::pmsc {

struct RelativePointErrors {
  static constexpr float kScale = 65535.0f;
  // n × N, column-major (a point's errors over every sample are contiguous, as the greedy
  // selection reads them). Rows no sample filled stay zero and are left out by the selection.
  Eigen::Matrix<std::uint16_t, Eigen::Dynamic, Eigen::Dynamic> u;

  // The point's error as read back: never above the error quantised.
  static double error(std::uint16_t relative, double max_error) {
    return static_cast<double>(relative) / static_cast<double>(kScale) * max_error;
  }
  // floor(e / e_max · kScale); e_max > 0, 0 ≤ e ≤ e_max. Inline: training quantises every point of
  // every held-out sample, and the quotient's divisor is the same along a sample.
  static std::uint16_t quantise(float value, float max_error) {
    const double scaled = std::floor(static_cast<double>(value) * (static_cast<double>(kScale) / max_error));
    auto relative = static_cast<std::uint16_t>(std::clamp(scaled, 0.0, static_cast<double>(kScale)));
    // The product may round up across a step: then the step below, so that what error() reads
    // back is never above the error.
    while (relative > 0 && error(relative, max_error) > static_cast<double>(value)) --relative;
    return relative;
  }
};

// select_check_points (check_points.h) on these errors: sample i is the selection's when
// counted[i] is non-zero and max_errors(i) ≥ noise_floor (> 0). Returns min(count, N − K) points.
std::vector<int> select_check_points(const RelativePointErrors& errors, const std::vector<char>& counted,
                                     const Eigen::VectorXd& max_errors, const std::vector<int>& key_points,
                                     const std::vector<int>& point_regions, int region_count, int count,
                                     double noise_floor);

}  // namespace animspace::pmsc
