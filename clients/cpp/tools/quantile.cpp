#include "clients/cpp/tools/quantile.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

namespace animspace::tools {

size_t nearest_rank(double q, size_t n) {
  assert(q >= 0 && q <= 1 && "a quantile is a fraction in [0, 1]");
  assert(n > 0);
  const double count = static_cast<double>(n);
  // q as written (0.07, 0.9) is not exact in binary, and q·n can land a few ulps above the integer
  // it means (0.07 × 100 = 7.000000000000001), which ⌈·⌉ would turn into the next rank. A relative
  // slack far above rounding error (ulps) and far below one rank (1/n) absorbs that.
  const double product = q * count;
  const double rank = std::ceil(product - 1e-9 * std::max(1.0, product));
  const auto k = static_cast<size_t>(std::max(rank, 1.0));
  assert(k <= n);
  return k;
}

double quantile(std::vector<double> samples, double q) {
  if (samples.empty()) return std::numeric_limits<double>::quiet_NaN();
  // Selection, not a full sort: the k-th smallest is all the definition needs.
  const auto k = static_cast<std::ptrdiff_t>(nearest_rank(q, samples.size()) - 1);
  std::nth_element(samples.begin(), samples.begin() + k, samples.end());
  return samples[static_cast<size_t>(k)];
}

}  // namespace animspace::tools
