#include "core/pmsc/calibration.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace animspace::pmsc {

double conformal_error_ratio(const Eigen::Ref<const Eigen::VectorXd>& key_point_errors,
                             const Eigen::Ref<const Eigen::VectorXd>& max_errors, double false_hit_rate,
                             double noise_floor, long* usable) {
  assert(key_point_errors.size() == max_errors.size());
  assert(false_hit_rate > 0 && false_hit_rate < 1);
  std::vector<double> scores;
  scores.reserve(static_cast<size_t>(key_point_errors.size()));
  for (Eigen::Index i = 0; i < key_point_errors.size(); ++i) {
    if (!(key_point_errors(i) >= noise_floor) || key_point_errors(i) <= 0) continue;
    scores.push_back(max_errors(i) / key_point_errors(i));
  }
  if (usable) *usable = static_cast<long>(scores.size());
  if (scores.empty()) return 1.0;
  const auto n = static_cast<long>(scores.size());
  // The ⌈(1 − δ)(n + 1)⌉-th smallest score, 1-based; past n the largest (see the header). The
  // small epsilon keeps an exact integer product (δ = 0.1, n = 9) from rounding up a rank.
  long rank = static_cast<long>(std::ceil((1.0 - false_hit_rate) * static_cast<double>(n + 1) - 1e-9));
  rank = std::clamp(rank, 1L, n);
  std::nth_element(scores.begin(), scores.begin() + (rank - 1), scores.end());
  return std::max(scores[static_cast<size_t>(rank - 1)], 1.0);
}

CalibratedEpsilon calibrate_epsilon_min(const Eigen::Ref<const Eigen::VectorXd>& key_point_errors,
                                        const Eigen::Ref<const Eigen::VectorXd>& max_errors,
                                        const std::vector<char>& from_block_fold, double tolerance,
                                        double false_hit_rate) {
  assert(key_point_errors.size() == max_errors.size());
  assert(static_cast<Eigen::Index>(from_block_fold.size()) == key_point_errors.size());
  CalibratedEpsilon out;
  out.epsilon_min = tolerance;
  for (char family : {0, 1}) {
    std::vector<double> bad;  // e_key of this family's held-out frames over the tolerance
    for (Eigen::Index i = 0; i < key_point_errors.size(); ++i) {
      if (from_block_fold[static_cast<size_t>(i)] == family && max_errors(i) > tolerance) {
        bad.push_back(key_point_errors(i));
      }
    }
    if (bad.empty()) continue;
    out.over_tolerance += static_cast<long>(bad.size());
    std::sort(bad.begin(), bad.end());
    const auto allowed = static_cast<size_t>(std::floor(false_hit_rate * static_cast<double>(bad.size() + 1) + 1e-9));
    // r ≥ 1 bad frames may be HIT (e_key ≤ ε_min includes b_(r)); r = 0: strictly below the first.
    const double epsilon = allowed >= 1 ? bad[std::min(allowed, bad.size()) - 1] : std::nextafter(bad[0], 0.0);
    out.epsilon_min = std::min(out.epsilon_min, epsilon);
  }
  if (out.over_tolerance == 0) {
    out.ratio_fallback = true;
    out.epsilon_min = tolerance / conformal_error_ratio(key_point_errors, max_errors, false_hit_rate,
                                                        kCalibrationNoiseFraction * tolerance);
  }
  return out;
}

OperatingPoint operating_point(const CalibrationSamples& samples, double false_hit_rate, double tolerance) {
  OperatingPoint point;
  point.false_hit_rate = false_hit_rate;
  point.epsilon_min = calibrate_epsilon_min(samples.key_point_errors, samples.max_errors, samples.from_block_fold,
                                            tolerance, false_hit_rate)
                          .epsilon_min;
  point.error_ratio = tolerance / point.epsilon_min;
  long hits = 0, flagged_over = 0;
  for (Eigen::Index i = 0; i < samples.size(); ++i) {
    const bool hit = samples.key_point_errors(i) <= point.epsilon_min;
    const bool over = samples.max_errors(i) > tolerance;
    hits += hit ? 1 : 0;
    point.over_tolerance += over ? 1 : 0;
    flagged_over += over && !hit ? 1 : 0;
    if (hit) point.worst_hit_error = std::max(point.worst_hit_error, samples.max_errors(i) / tolerance);
  }
  point.hit_rate = samples.size() > 0 ? static_cast<double>(hits) / static_cast<double>(samples.size()) : 0;
  point.miss_recall =
      point.over_tolerance > 0 ? static_cast<double>(flagged_over) / static_cast<double>(point.over_tolerance) : 1;
  return point;
}

std::vector<double> default_false_hit_rates() { return {0.005, 0.01, 0.02, 0.05, 0.1, 0.2}; }

}  // namespace animspace::pmsc
