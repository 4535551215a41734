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
                                        const std::vector<char>& fold_family, double tolerance,
                                        double false_hit_rate) {
  assert(key_point_errors.size() == max_errors.size());
  assert(static_cast<Eigen::Index>(fold_family.size()) == key_point_errors.size());
  CalibratedEpsilon out;
  out.epsilon_min = tolerance;
  for (char family : {kInterleavedFold, kBlockFold, kSparseFold}) {
    std::vector<double> bad;  // e_key of this family's held-out frames over the tolerance
    for (Eigen::Index i = 0; i < key_point_errors.size(); ++i) {
      if (fold_family[static_cast<size_t>(i)] == family && max_errors(i) > tolerance) {
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

Eigen::VectorXd CalibrationSamples::error_estimates(double key_weight, bool use_check) const {
  if (!use_check || !checked()) return key_point_errors;
  return (key_weight * key_point_errors).cwiseMax(check_point_errors);
}

Eigen::VectorXd CalibrationSamples::region_error_estimates(long region, double key_weight, bool use_check) const {
  if (!use_check || region_check_point_errors.cols() == 0) return region_key_point_errors.col(region);
  return (key_weight * region_key_point_errors.col(region)).cwiseMax(region_check_point_errors.col(region));
}

bool guarantee_holds(long bad_samples, double false_hit_rate) {
  return bad_samples > 0 && std::floor(false_hit_rate * static_cast<double>(bad_samples + 1) + 1e-9) >= 1;
}

ExtrapolatedEpsilon calibrate_extrapolated(const Eigen::Ref<const Eigen::VectorXd>& error_estimates,
                                           const Eigen::Ref<const Eigen::VectorXd>& max_errors, double tolerance,
                                           double false_hit_rate) {
  assert(error_estimates.size() == max_errors.size());
  assert(false_hit_rate > 0 && false_hit_rate < 1 && tolerance > 0);
  ExtrapolatedEpsilon out;
  std::vector<double> bad;  // each residual's estimate, extrapolated to e_max = tolerance
  bad.reserve(static_cast<size_t>(error_estimates.size()));
  for (Eigen::Index i = 0; i < error_estimates.size(); ++i) {
    out.over_tolerance += max_errors(i) > tolerance ? 1 : 0;
    if (!(max_errors(i) >= kCalibrationNoiseFraction * tolerance) || !std::isfinite(error_estimates(i))) continue;
    bad.push_back(error_estimates(i) * (tolerance / max_errors(i)));
  }
  out.bad_samples = static_cast<long>(bad.size());
  if (bad.empty()) {
    out.epsilon_min = 0;  // nothing to extrapolate: every held-out frame was reproduced exactly
    return out;
  }
  std::sort(bad.begin(), bad.end());
  const auto allowed = static_cast<size_t>(std::floor(false_hit_rate * static_cast<double>(bad.size() + 1) + 1e-9));
  // r ≥ 1 bad samples may be HIT (e ≤ ε_min includes e_(r)); r = 0: strictly below the first.
  out.epsilon_min = allowed >= 1 ? bad[std::min(allowed, bad.size()) - 1] : std::nextafter(bad[0], 0.0);
  return out;
}

namespace {

// Of the samples under the tolerance, those a calibrated ε calls HIT.
long good_hits(const Eigen::VectorXd& estimates, const Eigen::VectorXd& max_errors, double tolerance, double epsilon) {
  long hits = 0;
  for (Eigen::Index i = 0; i < estimates.size(); ++i) hits += max_errors(i) <= tolerance && estimates(i) <= epsilon;
  return hits;
}

}  // namespace

double choose_key_weight(const CalibrationSamples& samples, double tolerance) {
  if (!samples.checked() || samples.size() == 0) return 1;
  std::vector<double> ratios;
  for (Eigen::Index i = 0; i < samples.size(); ++i) {
    if (samples.key_point_errors(i) > 0 && samples.max_errors(i) >= kCalibrationNoiseFraction * tolerance) {
      ratios.push_back(samples.check_point_errors(i) / samples.key_point_errors(i));
    }
  }
  if (ratios.empty()) return 1;
  std::nth_element(ratios.begin(), ratios.begin() + static_cast<long>(ratios.size() / 2), ratios.end());
  const double base = std::max(ratios[ratios.size() / 2], 1e-12);
  // Candidates in order of preference, so that a tie keeps the one that weighs both terms most
  // evenly: w₀, w₀·2^±1, …, w₀·2^±4, and check points alone last.
  std::vector<double> candidates = {base};
  for (int k = 1; k <= 4; ++k) {
    candidates.push_back(base * std::ldexp(1.0, -k));
    candidates.push_back(base * std::ldexp(1.0, k));
  }
  candidates.push_back(0.0);
  double best_weight = base;
  long best_hits = -1;
  for (double weight : candidates) {
    const Eigen::VectorXd estimates = samples.error_estimates(weight);
    long hits = 0;  // over the whole operating range, not one δ (see the header)
    for (double rate : default_false_hit_rates()) {
      hits += good_hits(estimates, samples.max_errors, tolerance,
                        calibrate_extrapolated(estimates, samples.max_errors, tolerance, rate).epsilon_min);
    }
    if (hits > best_hits) {
      best_hits = hits;
      best_weight = weight;
    }
  }
  return best_weight;
}

OperatingPoint operating_point(const CalibrationSamples& samples, double key_weight, double false_hit_rate,
                               double tolerance) {
  OperatingPoint point;
  point.false_hit_rate = false_hit_rate;
  const Eigen::VectorXd estimates = samples.error_estimates(key_weight);
  const ExtrapolatedEpsilon calibrated = calibrate_extrapolated(estimates, samples.max_errors, tolerance, false_hit_rate);
  point.epsilon_min = calibrated.epsilon_min;
  point.bad_samples = calibrated.bad_samples;
  point.error_ratio = point.epsilon_min > 0 ? tolerance / point.epsilon_min : 0;
  long hits = 0, flagged_over = 0;
  for (Eigen::Index i = 0; i < samples.size(); ++i) {
    const bool hit = estimates(i) <= point.epsilon_min;
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
