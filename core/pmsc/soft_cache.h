// Soft caching and fail-through (Meyer & Anderson 2006 §5; 2007 §2.3, eqs. 8–11).
//
// The RMS key-point error e_key decides how far the subspace estimate f̂ can be trusted:
//   e_key ≤ ε_min          → hit:   out = f̂
//   e_key ≥ ε_max          → miss:  out = f
//   otherwise              → blend: out = α f + (1 − α) f̂,  α = (e_key − ε_min) / (ε_max − ε_min)
// The transition zone keeps an animated sequence from popping when it crosses the threshold.
#pragma once

#include <Eigen/Core>

#include "core/common/result.h"

namespace animspace::pmsc {

enum class CacheStatus { kHit, kBlend, kMiss };

const char* cache_status_name(CacheStatus status);

// [ε_min, ε_max] on the RMS key-point error, model units; 0 ≤ ε_min ≤ ε_max.
struct SoftCacheThresholds {
  double epsilon_min = 0;
  double epsilon_max = 0;
};

// Errors: kInvalidArgument naming the field for negative, non-finite or inverted thresholds.
Status validate(const SoftCacheThresholds& thresholds);

struct SoftCacheDecision {
  CacheStatus status = CacheStatus::kHit;
  // Weight of the full calculation in the output, α ∈ [0, 1]: 0 for a hit, 1 for a miss.
  double alpha = 0;
};

// Applies eqs. 9–11. When ε_min == ε_max the zone is empty: a hit up to and including ε_min, a
// miss above. `key_point_error` must not be negative (asserted); NaN or +Inf is a miss.
SoftCacheDecision decide(double key_point_error, const SoftCacheThresholds& thresholds);

// out = α·full + (1 − α)·estimate, element-wise (eq. 11). Sizes must match (asserted).
void blend(const Eigen::Ref<const Eigen::VectorXf>& estimate, const Eigen::Ref<const Eigen::VectorXf>& full,
           double alpha, Eigen::Ref<Eigen::VectorXf> out);

}  // namespace animspace::pmsc
