// Merry 2007, "Animation space" (PhD thesis), Appendix A.2: minimising a quadric subject to
// linear constraints, with the least-norm tie-break for a singular P.
#include "core/lod/constrained_least_squares.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

namespace animspace::lod {
namespace {

// P's symmetry, relative to its largest entry (as for the metrics: P is built symmetric up to
// rounding, anything larger is a corrupt matrix).
constexpr double kSymmetryTolerance = 1e-9;
// Eigenvalues below −kNegativeEigenvalueTolerance·λ_max make P indefinite; those in between are
// rounding of a true 0.
constexpr double kNegativeEigenvalueTolerance = 1e-9;
// Eigenvalues at or below kZeroEigenvalueTolerance·λ_max are weights of 0 (A.2.3): rounding in
// the eigensolver is O(n ε λ_max), far below this.
constexpr double kZeroEigenvalueTolerance = 1e-12;
// A is rank deficient when σ_min(A) ≤ kRankTolerance·σ_max(A).
constexpr double kRankTolerance = 1e-12;
// A row of R₂ (A.2.3) is zero when its pivot is at or below kPivotTolerance·σ_max(A). The
// zero-weight columns of AU carry the error of the computed null space of P (ε λ_max / gap, the
// gap being P's smallest positive eigenvalue), so a constraint that is orthogonal to P's null
// space in exact arithmetic shows up as a pivot of that size, and taking it as non-zero moves x by
// rhs/pivot along a direction that only looks free. A metric sampled from few poses has gaps near
// 1e-12 λ_max: at the earlier floor of 1e-10 the cow rig's P from 16 poses gave corrections of
// norm ~1e10 that cost far more than they should and broke Σ s_w = 0 (levels with p̲ = 0.999996,
// coarse-level errors of 8e4 where 200 poses give 97). At 1e-6 such a constraint is met in P's
// range instead, at a cost that is finite and measured; with a well-sampled P the levels barely
// move (cow, 200 poses: ε of levels 1–12 within 3.5 %; the 9- and 4-vertex levels 19 % and 44 %
// higher).
constexpr double kPivotTolerance = 1e-6;

// Refinement of K towards A K = I (below): steps at most, and the residual that needs none.
constexpr int kRefinementSteps = 3;
constexpr double kRefinedResidual = 1e-14;

Error invalid(std::string message) { return make_error(ErrorCode::kInvalidArgument, std::move(message)); }

std::string shape(const Eigen::MatrixXd& M) { return std::to_string(M.rows()) + " × " + std::to_string(M.cols()); }

// M⁺ for M (k × n) of full row rank k ≤ n: the operator of A.2.1, y = M⁺ d the least-norm
// solution of M y = d. The thesis's Gram–Schmidt L M = Q is the QR factorisation Mᵀ = Q R with
// L = R⁻ᵀ, so y = Q R⁻ᵀ d. Returns false if R is numerically singular (|r_ii| at or below
// `pivot_floor`), i.e. the rows were not independent after all.
bool minimum_norm_operator(const Eigen::MatrixXd& M, double pivot_floor, Eigen::MatrixXd& out) {
  const Eigen::Index k = M.rows();
  const Eigen::Index n = M.cols();
  out.setZero(n, k);
  if (k == 0) return true;
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(M.transpose());
  const Eigen::MatrixXd R = qr.matrixQR().topRows(k).triangularView<Eigen::Upper>();
  for (Eigen::Index i = 0; i < k; ++i) {
    if (!(std::abs(R(i, i)) > pivot_floor)) return false;
  }
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(n, k);
  // R⁻ᵀ = (Rᵀ)⁻¹, a lower-triangular solve.
  const Eigen::MatrixXd L =
      R.transpose().triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(k, k));
  out = Q * L;
  return true;
}

}  // namespace

Result<DiagonalisedQuadric> diagonalise(const Eigen::MatrixXd& P) {
  if (P.rows() != P.cols()) return invalid("P is " + shape(P) + ", expected square");
  if (!P.allFinite()) return invalid("P has a NaN or infinite entry");
  const double scale = P.cwiseAbs().maxCoeff();
  if ((P - P.transpose()).cwiseAbs().maxCoeff() > kSymmetryTolerance * scale) return invalid("P is not symmetric");
  // A.2.4: P = UΛUᵀ. The solver reads one triangle, so hand it the symmetric part.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(0.5 * (P + P.transpose()));
  if (eigen.info() != Eigen::Success) {
    return make_error(ErrorCode::kInternal, "eigendecomposition of P did not converge");
  }
  DiagonalisedQuadric out;
  out.lambda = eigen.eigenvalues();
  out.U = eigen.eigenvectors();
  out.lambda_max = std::max(out.lambda.maxCoeff(), 0.0);
  if (out.lambda.minCoeff() < -kNegativeEigenvalueTolerance * out.lambda_max) {
    return invalid("P is not positive semi-definite: eigenvalue " + std::to_string(out.lambda.minCoeff()) +
                   " below −" + std::to_string(kNegativeEigenvalueTolerance * out.lambda_max));
  }
  return out;
}

Result<Eigen::MatrixXd> constrained_least_squares_operator(const Eigen::MatrixXd& P, const Eigen::MatrixXd& A) {
  Result<DiagonalisedQuadric> quadric = diagonalise(P);
  if (!quadric.ok()) return quadric.error();
  return constrained_least_squares_operator(*quadric, A);
}

Result<Eigen::MatrixXd> constrained_least_squares_operator(const DiagonalisedQuadric& quadric,
                                                           const Eigen::MatrixXd& A) {
  const Eigen::Index n = quadric.U.rows();
  const Eigen::Index m = A.rows();
  if (A.cols() != n) {
    return invalid("A is " + shape(A) + ", expected " + std::to_string(n) + " columns (the size of P)");
  }
  if (m == 0 || m > n) {
    return invalid("A has " + std::to_string(m) + " constraints, expected between 1 and " + std::to_string(n) +
                   " (the number of unknowns)");
  }
  if (!A.allFinite()) return invalid("A has a NaN or infinite entry");

  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A);
  const Eigen::VectorXd sigma = svd.singularValues();
  const double sigma_max = sigma(0);
  if (!(sigma(m - 1) > kRankTolerance * sigma_max)) {
    return invalid("A is rank deficient: smallest singular value " + std::to_string(sigma(m - 1)) + " of " +
                   std::to_string(sigma_max) + ", expected " + std::to_string(m) + " independent constraints");
  }

  // A.2.4: with x̂ = Uᵀx and Â = AU the problem is min Σ λ_i x̂_i² s.t. Â x̂ = b.
  const Eigen::VectorXd& lambda = quadric.lambda;
  const Eigen::MatrixXd& U = quadric.U;
  const double lambda_max = quadric.lambda_max;

  // A.2.3: split the variables into positive weights (x̂₁) and zero weights (x̂₂).
  std::vector<Eigen::Index> positive;
  std::vector<Eigen::Index> zero;
  for (Eigen::Index i = 0; i < n; ++i) {
    (lambda(i) > kZeroEigenvalueTolerance * lambda_max ? positive : zero).push_back(i);
  }
  const auto p = static_cast<Eigen::Index>(positive.size());
  const auto z = static_cast<Eigen::Index>(zero.size());
  Eigen::MatrixXd U1(n, p);
  Eigen::MatrixXd U2(n, z);
  Eigen::VectorXd sqrt_lambda(p);
  for (Eigen::Index k = 0; k < p; ++k) {
    U1.col(k) = U.col(positive[static_cast<size_t>(k)]);
    sqrt_lambda(k) = std::sqrt(lambda(positive[static_cast<size_t>(k)]));
  }
  for (Eigen::Index k = 0; k < z; ++k) U2.col(k) = U.col(zero[static_cast<size_t>(k)]);
  const Eigen::MatrixXd A1 = A * U1;  // m × p
  const Eigen::MatrixXd A2 = A * U2;  // m × z

  // A.2.3: A₂ = Q₂R₂ (column-pivoted, so that R₂'s zero rows come last and are recognised even
  // when A₂ is rank deficient); multiplying the constraints by Q₂ᵀ gives
  //   Q₂ᵀA₁ x̂₁ + R₂ x̂₂ = Q₂ᵀ b,
  // whose last m − r rows (R₂'s zero rows) constrain x̂₁ alone.
  Eigen::MatrixXd QtT = Eigen::MatrixXd::Identity(m, m);  // Q₂ᵀ
  Eigen::MatrixXd R2top(0, z);                            // R₂'s non-zero rows, columns pivoted
  Eigen::Index r = 0;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr2;
  if (z > 0) {
    qr2.compute(A2);
    const double pivot_floor = kPivotTolerance * sigma_max;
    const Eigen::Index diagonal = std::min(m, z);
    // Column pivoting makes |r_ii| non-increasing, so the non-zero rows are the leading ones.
    while (r < diagonal && std::abs(qr2.matrixR()(r, r)) > pivot_floor) ++r;
    QtT = qr2.householderQ().transpose();
    R2top = qr2.matrixR().topRows(r).triangularView<Eigen::Upper>();
  }
  const Eigen::MatrixXd QtA1 = QtT * A1;  // m × p

  // A.2.2 on the m − r rows without x̂₂: with S = diag(√λ), y = S x̂₁ and B = C S⁻¹ the weighted
  // problem min Σ λ x̂₁² s.t. C x̂₁ = d becomes min ‖y‖ s.t. B y = d (A.2.1). C has full row rank
  // because A does; B spans the same as C. d = (Q₂ᵀ b)_bottom, so as an operator on b:
  //   x̂₁ = S⁻¹ B⁺ (Q₂ᵀ)_bottom b.
  const Eigen::Index free_rows = m - r;
  Eigen::MatrixXd K1 = Eigen::MatrixXd::Zero(p, m);
  if (free_rows > 0) {
    if (p < free_rows) {
      return invalid("the constraints cannot be met: " + std::to_string(free_rows) +
                     " constraints fall on P's range, which has dimension " + std::to_string(p));
    }
    const Eigen::MatrixXd B = QtA1.bottomRows(free_rows) * sqrt_lambda.cwiseInverse().asDiagonal();
    Eigen::MatrixXd B_pinv;
    if (!minimum_norm_operator(B, kRankTolerance * B.norm(), B_pinv)) {
      return invalid("A's constraints are numerically dependent on the range of P (rank below " +
                     std::to_string(m) + " after splitting off P's null space)");
    }
    K1 = sqrt_lambda.cwiseInverse().asDiagonal() * B_pinv * QtT.bottomRows(free_rows);
  }

  // A.2.3, last step: x̂₂ meets the first r rows, R₂ x̂₂ = (Q₂ᵀ b)_top − (Q₂ᵀA₁)_top x̂₁. x̂₂ has zero
  // weight, so the objective does not care; its least-norm solution (A.2.1) makes ‖x‖ = ‖x̂‖
  // least among the minimisers and handles a rank-deficient R₂ predictably.
  Eigen::MatrixXd K2 = Eigen::MatrixXd::Zero(z, m);
  if (r > 0) {
    Eigen::MatrixXd R2_pinv;
    // The first r pivots all exceed the floor, so R₂top has full row rank.
    const bool full_rank = minimum_norm_operator(R2top, 0.0, R2_pinv);
    if (!full_rank) return make_error(ErrorCode::kInternal, "R₂ lost rank after pivoting");
    const Eigen::MatrixXd rhs = QtT.topRows(r) - QtA1.topRows(r) * K1;  // r × m
    K2 = qr2.colsPermutation() * (R2_pinv * rhs);
  }

  // Back from x̂ to x = U x̂ (A.2.4).
  Eigen::MatrixXd K = U1 * K1 + U2 * K2;

  // R₂'s rows below the floor are taken as zero, but they are not exactly zero, so x̂₂ leaves a
  // residual in them: A K is off the identity by up to the floor times x̂₂ (9e-11 on the weight
  // constraint Σ s_w = 0 for a metric from 8 poses). Refinement towards a right inverse,
  // K ← K (2I − A K), squares the residual each step; K b stays the optimum for constraints b'
  // within that residual of b.
  const Eigen::MatrixXd identity = Eigen::MatrixXd::Identity(m, m);
  double residual = (A * K - identity).cwiseAbs().maxCoeff();
  for (int step = 0; step < kRefinementSteps && residual > kRefinedResidual; ++step) {
    const Eigen::MatrixXd refined = K * (2 * identity - A * K);
    const double refined_residual = (A * refined - identity).cwiseAbs().maxCoeff();
    if (!(refined_residual < residual)) break;  // at rounding already
    K = refined;
    residual = refined_residual;
  }
  return K;
}

Result<Eigen::VectorXd> constrained_least_squares(const Eigen::MatrixXd& P, const Eigen::MatrixXd& A,
                                                  const Eigen::VectorXd& b) {
  if (b.size() != A.rows()) {
    return invalid("b has " + std::to_string(b.size()) + " entries, expected " + std::to_string(A.rows()) +
                   " (one per row of A)");
  }
  if (!b.allFinite()) return invalid("b has a NaN or infinite entry");
  Result<Eigen::MatrixXd> K = constrained_least_squares_operator(P, A);
  if (!K.ok()) return K.error();
  // x = K b: the solution is linear in b (A.2.1–A.2.4 apply only linear maps to b).
  return Eigen::VectorXd(*K * b);
}

}  // namespace animspace::lod
