// Minimising a quadric subject to linear constraints (Merry 2007 Appendix A.2), the solver
// behind influence simplification (§6.3).
//
//   minimise xᵀPx  subject to  Ax = b,  and among the minimisers the one of least ‖x‖₂
//
// with P (n × n) symmetric non-negative definite — possibly singular: P = E[GᵀG] has a null
// space for every fixed-translation model (Appendix B.3), which is why the thesis needs the
// tie-break — and A (m × n) of full row rank m ≤ n. The solution is built as the appendix does:
// diagonalise P = UΛUᵀ (A.2.4), split the variables into positive and zero weights (A.2.3), scale
// the positive ones (A.2.2) and take the minimum-norm solution of the rest (A.2.1).
//
// The solution is linear in b, x = K b, and K depends only on P and A. Influence simplification
// meets the same (influence set, removed bone) pair at many vertices, so it computes K once and
// reuses it (the thesis kept the last 128 pairs, §6.3).
#pragma once

#include <Eigen/Core>

#include "core/common/result.h"

namespace animspace::lod {

// P = UΛUᵀ (A.2.4), validated: what every operator for the same P shares.
struct DiagonalisedQuadric {
  Eigen::VectorXd lambda;  // eigenvalues, ascending
  Eigen::MatrixXd U;       // orthonormal eigenvectors
  double lambda_max = 0;
};

// Errors: kInvalidArgument when P is not square, has a non-finite entry, is not symmetric (1e-9
// relative) or not non-negative definite (an eigenvalue below −1e-9 λ_max); kInternal when the
// eigensolver does not converge.
Result<DiagonalisedQuadric> diagonalise(const Eigen::MatrixXd& P);

// K for a P diagonalised once (influence simplification meets the same P_I with several
// removed bones); errors as below for A.
Result<Eigen::MatrixXd> constrained_least_squares_operator(const DiagonalisedQuadric& quadric, const Eigen::MatrixXd& A);

// K (n × m) with x = K b for every b, refined so that A K = I to rounding. Eigenvalues of P at or
// below 1e-12 · λ_max count as zero (rounding on the null space).
// Errors: kInvalidArgument when P is not square, A's column count differs from P's size, m = 0 or
// m > n, an entry is not finite, P is not symmetric (1e-9 relative) or not non-negative definite
// (an eigenvalue below −1e-9 λ_max), or A is rank deficient (1e-12 relative).
Result<Eigen::MatrixXd> constrained_least_squares_operator(const Eigen::MatrixXd& P, const Eigen::MatrixXd& A);

// x for one right-hand side b (m entries); same errors, plus a b of the wrong size.
Result<Eigen::VectorXd> constrained_least_squares(const Eigen::MatrixXd& P, const Eigen::MatrixXd& A,
                                                  const Eigen::VectorXd& b);

}  // namespace animspace::lod
