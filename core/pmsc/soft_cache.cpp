#include "core/pmsc/soft_cache.h"

#include <cassert>
#include <cmath>
#include <string>

namespace animspace::pmsc {

const char* cache_status_name(CacheStatus status) {
  switch (status) {
    case CacheStatus::kHit: return "hit";
    case CacheStatus::kBlend: return "blend";
    case CacheStatus::kMiss: return "miss";
  }
  return "unknown";
}

Status validate(const SoftCacheThresholds& t) {
  if (!std::isfinite(t.epsilon_min) || t.epsilon_min < 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "epsilon_min must be finite and ≥ 0, got " + std::to_string(t.epsilon_min));
  }
  if (!std::isfinite(t.epsilon_max) || t.epsilon_max < t.epsilon_min) {
    return make_error(ErrorCode::kInvalidArgument, "epsilon_max must be finite and ≥ epsilon_min (" +
                                                       std::to_string(t.epsilon_min) + "), got " +
                                                       std::to_string(t.epsilon_max));
  }
  return Status::Ok();
}

SoftCacheDecision decide(double key_point_error, const SoftCacheThresholds& t) {
  assert(!(key_point_error < 0));
  // An error that is not a number cannot vouch for the estimate: the full calculation decides.
  if (std::isnan(key_point_error)) return {CacheStatus::kMiss, 1.0};
  if (key_point_error <= t.epsilon_min) return {CacheStatus::kHit, 0.0};
  if (key_point_error >= t.epsilon_max) return {CacheStatus::kMiss, 1.0};
  return {CacheStatus::kBlend, (key_point_error - t.epsilon_min) / (t.epsilon_max - t.epsilon_min)};
}

void blend(const Eigen::Ref<const Eigen::VectorXf>& estimate, const Eigen::Ref<const Eigen::VectorXf>& full,
           double alpha, Eigen::Ref<Eigen::VectorXf> out) {
  assert(estimate.size() == full.size() && out.size() == full.size());
  const float a = static_cast<float>(alpha);
  out = a * full + (1.0f - a) * estimate;
}

}  // namespace animspace::pmsc
