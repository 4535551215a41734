// The one definition of a sample quantile ("p50", "p99") for the tools that report latencies and
// errors: animspace-bench's tables and animspace-loadtest's histogram, so that a p99 printed by
// one means what it means in the other.
//
// Nearest rank — Hyndman & Fan 1996, "Sample quantiles in statistical packages", definition 1, the
// inverse of the empirical distribution function: the q-quantile of n samples is the k-th smallest,
// k = max(1, ⌈q·n⌉). Chosen over interpolation (their definition 7, numpy's default) because it is
// always a value that was measured — a p99 latency some call really had — and because it is the
// rule a bucketed histogram can apply exactly (loadtest/histogram.h; HdrHistogram does the same).
// Samples 10, 20, 30, 40: p50 = 20, p75 = 30, p99 = 40, p0 = 10.
#pragma once

#include <cstddef>
#include <vector>

namespace animspace::tools {

// The 1-based rank k = max(1, ⌈q·n⌉) of the q-quantile among n ≥ 1 samples, q ∈ [0, 1]; 1 ≤ k ≤ n.
size_t nearest_rank(double q, size_t n);

// The q-quantile (q ∈ [0, 1]) of `samples`, in any order: the nearest_rank(q, n)-th smallest.
// NaN for no samples, so that an empty run prints as nan / null rather than as a 0 latency.
double quantile(std::vector<double> samples, double q);

}  // namespace animspace::tools
