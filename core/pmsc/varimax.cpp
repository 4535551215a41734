// Varimax by sweeps of pairwise plane rotations (Kaiser 1958; Harman 1976), as used for
// key-point selection by Meyer & Anderson 2006 §4 / 2007 §2.2.
#include "core/pmsc/varimax.h"

#include <cassert>
#include <cmath>
#include <utility>

#include <Eigen/Jacobi>

namespace animspace::pmsc {

using Eigen::Index;
using Eigen::MatrixXd;

namespace {

// The sums of the plane-angle formula for columns x and y (n entries each): with u = x² − y²
// and v = 2xy, A = Σu, B = Σv, C = Σ(u² − v²), D = 2Σuv. One fused pass with two sets of
// accumulators (independent add chains) — this loop is where varimax spends its time.
struct PlaneSums {
  double A = 0.0, B = 0.0, C = 0.0, D = 0.0;
};

PlaneSums plane_sums(const double* x, const double* y, Index n) {
  double a[2] = {0.0, 0.0}, b[2] = {0.0, 0.0}, c[2] = {0.0, 0.0}, d[2] = {0.0, 0.0};
  const auto add = [&](int lane, Index i) {
    const double u = x[i] * x[i] - y[i] * y[i];
    const double v = 2.0 * x[i] * y[i];
    a[lane] += u;
    b[lane] += v;
    c[lane] += u * u - v * v;
    d[lane] += u * v;
  };
  Index i = 0;
  for (; i + 1 < n; i += 2) {
    add(0, i);
    add(1, i + 1);
  }
  if (i < n) add(0, i);
  return {a[0] + a[1], b[0] + b[1], c[0] + c[1], 2.0 * (d[0] + d[1])};
}

}  // namespace

double varimax_criterion(const MatrixXd& loadings) {
  assert(loadings.rows() >= 1);
  double criterion = 0.0;
  for (Index j = 0; j < loadings.cols(); ++j) {
    const Eigen::ArrayXd squares = loadings.col(j).array().square();
    criterion += (squares - squares.mean()).square().mean();
  }
  return criterion;
}

VarimaxResult varimax(const MatrixXd& loadings, int max_iterations, double tolerance,
                      VarimaxNormalization normalization) {
  assert(loadings.rows() >= 1 && max_iterations >= 0 && tolerance > 0.0);
  assert(loadings.allFinite());
  const Index R = loadings.rows(), k = loadings.cols();

  // 1. Λ, the matrix whose criterion is maximised: the loadings, or their rows scaled to unit
  //    length (Kaiser). Row scaling commutes with the rotation, so loadings·Q is the answer
  //    either way.
  MatrixXd normalized;
  const MatrixXd* L = &loadings;
  if (normalization == VarimaxNormalization::kKaiser) {
    normalized = loadings;
    for (Index i = 0; i < R; ++i) {
      const double length = normalized.row(i).norm();
      if (length > 0.0) normalized.row(i) /= length;
    }
    L = &normalized;
  }

  VarimaxResult result;
  result.rotation = MatrixXd::Identity(k, k);
  result.criterion_before = varimax_criterion(*L);
  result.criterion_after = result.criterion_before;
  if (k <= 1 || (L->array() == 0.0).all()) {
    result.rotated = loadings;
    result.converged = true;
    return result;
  }

  // 2. Sweeps of plane rotations (Kaiser 1958; Harman 1976). For columns x, y of Z = ΛQ
  //    and u = x² − y², v = 2xy, rotating the pair by φ (x' = x cos φ + y sin φ,
  //    y' = −x sin φ + y cos φ) changes R·V by
  //      ¼ [cos 4φ (C − (A² − B²)/R) + sin 4φ (D − 2AB/R)] + const,
  //    A = Σu, B = Σv, C = Σ(u² − v²), D = 2Σuv: the best angle in the plane is
  //    4φ = atan2(D − 2AB/R, C − (A² − B²)/R) (the derivation: with z = x + iy, u + iv = z², and
  //    x'⁴ + y'⁴ = (|z|⁴ + u'²)/2 with u' = u cos 2φ + v sin 2φ).
  const auto rows = static_cast<double>(R);
  MatrixXd Q = MatrixXd::Identity(k, k);
  MatrixXd Z = *L;
  MatrixXd best_rotation = Q;
  double best = result.criterion_before;
  while (result.iterations < max_iterations) {
    for (Index j = 0; j + 1 < k; ++j) {
      for (Index l = j + 1; l < k; ++l) {
        const PlaneSums sums = plane_sums(Z.col(j).data(), Z.col(l).data(), R);
        const double numerator = sums.D - 2.0 * sums.A * sums.B / rows;
        const double denominator = sums.C - (sums.A * sums.A - sums.B * sums.B) / rows;
        if (numerator == 0.0 && denominator >= 0.0) continue;  // already the plane's best
        const double phi = 0.25 * std::atan2(numerator, denominator);
        // Eigen applies Gᵀ on the right for G = JacobiRotation(c, s): x ← c·x − s·y. Passing −s
        // gives our x ← c·x + s·y, y ← −s·x + c·y (vectorised).
        const Eigen::JacobiRotation<double> plane(std::cos(phi), -std::sin(phi));
        Z.applyOnTheRight(j, l, plane);
        Q.applyOnTheRight(j, l, plane);
      }
    }
    ++result.iterations;
    // Z = ΛQ afresh each sweep, so that rounding in the plane rotations does not accumulate.
    Z.noalias() = *L * Q;
    const double next = varimax_criterion(Z);
    const double increase = next - best;
    // Every step is an exact plane maximum, so a loss can only be rounding at the optimum; the
    // best rotation seen is kept all the same, which makes criterion_after >= criterion_before
    // hold to the last bit.
    if (next > best) {
      best = next;
      best_rotation = Q;
    }
    if (increase <= tolerance * best) {
      result.converged = true;
      break;
    }
  }

  // 3. A product of plane rotations, so det = +1.
  result.criterion_after = best;
  result.rotated.noalias() = loadings * best_rotation;
  result.rotation = std::move(best_rotation);
  return result;
}

}  // namespace animspace::pmsc
