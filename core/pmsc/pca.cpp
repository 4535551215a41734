// Thin PCA through the Gram matrix, and the incremental choice of M (Meyer & Anderson 2006 §3,
// 2007 §2.1).
#include "core/pmsc/pca.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <numeric>
#include <utility>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Householder>
#include <Eigen/QR>

#include "core/common/kernels.h"
#include "core/common/parallel.h"

namespace animspace::pmsc {
namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// Why kRelativeSingularValueFloor = 1e-7. The Gram matrix squares the condition number: its
// eigenvalues λ_i = σ_i² carry an absolute error of a small multiple of eps·σ_0² (rounding in
// XᵀX plus a backward-stable eigensolver), so σ_i below sqrt(eps)·σ_0 ≈ 1.5e-8·σ_0 cannot be
// told from zero through λ_i. We do not read σ_i off λ_i, though: σ_i = ‖X v_i‖ is accurate to
// second order in the eigenvector error, and for a null direction it comes out near
// eps·σ_0·(σ_0/σ_r) — far below the floor for any training matrix whose kept directions are
// better conditioned than 1e7. 1e-7 leaves a margin of ~7 over sqrt(eps) for the directions that
// are kept (their eigenvectors are contaminated by the dominant ones by at most
// eps·σ_0²/σ_i² ≈ 2%, which the re-orthonormalisation below removes) and sits at the resolution
// of the float32 points X is built from (6e-8), so nothing a rig can express is dropped.
// (Measured on 30006 × 88: σ_i = 1.2e-7·σ_0 is kept and matches the exact value to 6 digits;
// 9e-8·σ_0 is dropped.)

// Gram–Schmidt-equivalent re-orthonormalisation of U (R × k), keeping column order and signs
// (column j only loses its components along columns 0 … j-1). Columns come in with unit norm
// and near-orthogonal (off-diagonals of UᵀU up to ~eps·σ_0²/(σ_i σ_j)), so Cholesky QR —
// U ← U L⁻ᵀ with L Lᵀ = UᵀU — is stable (orthogonality error ~eps·κ(U)²) and costs a
// SYRK (R·k² flops) and a GEMM (2·R·k²). Should UᵀU be far from I (not seen in practice), a
// Householder QR (2·R·k² flops, unconditionally stable) takes over.
void reorthonormalize(MatrixXd& U) {
  const Index k = U.cols();
  if (k == 0) return;
  MatrixXd gram = MatrixXd::Zero(k, k);
  gram_lower_serial(U.rows(), k, U.data(), U.outerStride(), gram.data(), k);
  gram = gram.selfadjointView<Eigen::Lower>();
  // ‖UᵀU − I‖_F < 1/2 bounds κ(U)² by 3.
  if ((gram - MatrixXd::Identity(k, k)).norm() < 0.5) {
    const Eigen::LLT<MatrixXd> llt(gram);
    if (llt.info() == Eigen::Success) {
      // U L⁻ᵀ as one product with the explicit inverse (upper triangular, κ ≤ √3, so forming it
      // costs no accuracy) through the dispatched kernel rather than Eigen/SSE2's triangular
      // solve: 300k × 256² for the papers' 100k illumination points. A block of rows at a time,
      // in place: at studio sizes U is the largest thing the PCA holds (issue #53).
      MatrixXd inverse = MatrixXd::Identity(k, k);
      llt.matrixU().solveInPlace(inverse);
      const Index block_rows = TrainingMatrix::kBlockRows;
      MatrixXd product(std::min(block_rows, U.rows()), k);
      for (Index r0 = 0; r0 < U.rows(); r0 += block_rows) {
        const Index n = std::min(block_rows, U.rows() - r0);
        gemm_serial(n, k, k, U.data() + r0, U.outerStride(), inverse.data(), k, 0.0, product.data(), product.rows());
        U.middleRows(r0, n) = product.topRows(n);
      }
      return;
    }
  }
  const Eigen::HouseholderQR<MatrixXd> qr(U);
  MatrixXd Q = MatrixXd::Identity(U.rows(), k);
  Q.applyOnTheLeft(qr.householderQ());
  // Householder leaves diag(R) with either sign; flip so that Q's column j points the way U's
  // did (R_jj > 0), as Gram–Schmidt would.
  for (Index j = 0; j < k; ++j) {
    if (qr.matrixQR()(j, j) < 0.0) Q.col(j) = -Q.col(j);
  }
  U = std::move(Q);
}

// Makes each column's entry of largest magnitude positive (the first one on ties), so that the
// basis is a function of X alone and not of the eigensolver's arbitrary signs.
void fix_signs(MatrixXd& U) {
  for (Index j = 0; j < U.cols(); ++j) {
    Index largest = 0;
    U.col(j).cwiseAbs().maxCoeff(&largest);
    if (U(largest, j) < 0.0) U.col(j) = -U.col(j);
  }
}

// Steps 2 and 3 of a thin PCA from its candidate directions U (R × k, columns X v_i) and their
// σ_i: order by σ (‖X v_i‖ can swap neighbours of a near-degenerate pair), drop directions below
// the floor, a_i = X v_i / σ_i, then one re-orthonormalisation and the sign convention. In U's
// own storage.
PcaBasis basis_from_directions(MatrixXd U, const VectorXd& sigma) {
  const Index R = U.rows(), candidates = U.cols();
  PcaBasis pca{MatrixXd(R, 0), VectorXd(0)};
  if (candidates == 0) return pca;
  std::vector<Index> order(static_cast<size_t>(candidates));
  std::iota(order.begin(), order.end(), Index{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](Index a, Index b) { return sigma(a) > sigma(b); });
  const double sigma_0 = sigma(order.front());
  if (!(sigma_0 > 0.0)) return pca;
  const double sigma_floor = kRelativeSingularValueFloor * sigma_0;
  const auto kept = static_cast<Index>(
      std::count_if(order.begin(), order.end(), [&](Index i) { return sigma(i) > sigma_floor; }));
  // Column j of the result is column order[j] of U: a permutation applied in place follows its
  // cycles, column by column.
  Eigen::PermutationMatrix<Eigen::Dynamic> permutation(candidates);
  for (Index j = 0; j < candidates; ++j) permutation.indices()(j) = static_cast<int>(order[static_cast<size_t>(j)]);
  U = U * permutation;
  pca.singular_values.resize(kept);
  for (Index j = 0; j < kept; ++j) {
    pca.singular_values(j) = sigma(order[static_cast<size_t>(j)]);
    U.col(j) /= pca.singular_values(j);
  }
  if (kept < candidates) U.conservativeResize(R, kept);
  pca.basis = std::move(U);
  reorthonormalize(pca.basis);
  fix_signs(pca.basis);
  return pca;
}

}  // namespace

MatrixXd leading_gram_eigenvectors(const MatrixXd& gram, int count) {
  assert(count >= 0 && gram.rows() == gram.cols());
  const Index F = gram.rows();
  const Index k = std::min<Index>(count, F);
  if (k == 0) return MatrixXd(F, 0);
  // The eigensolver reads the lower triangle only.
  const Eigen::SelfAdjointEigenSolver<MatrixXd> eigen(gram, Eigen::ComputeEigenvectors);
  // Eigenvalues come ascending: the largest k are the rightmost columns.
  return eigen.eigenvectors().rightCols(k).rowwise().reverse();
}

PcaBasis pca_from_directions(MatrixXd directions) {
  const VectorXd sigma = directions.colwise().norm().transpose();
  return basis_from_directions(std::move(directions), sigma);
}

PcaBasis thin_pca(const TrainingMatrix& X, int max_vectors) {
  assert(max_vectors >= 0);
  const Index R = X.rows(), F = X.cols();
  const Index candidates = std::min<Index>(max_vectors, std::min(R, F));
  if (candidates == 0) return PcaBasis{MatrixXd(R, 0), VectorXd(0)};
  if (F < R) {
    // Only the lower triangle of XᵀX is formed (SYRK, R·F²/2 flops). X V through the dispatched
    // kernel: in Eigen/SSE2, products of this shape were 15% of the key selection's profile at
    // the papers' 100k illumination points (300k × 324 × 12, once per iteration).
    const MatrixXd V = leading_gram_eigenvectors(X.gram(), static_cast<int>(candidates));
    MatrixXd U;
    X.times(V, U);
    return pca_from_directions(std::move(U));
  }
  // Wide (or square) X: the Gram matrix on either side is no smaller than X itself, so take the
  // SVD directly; its U is already orthonormal and σ_i accurate to eps·σ_0.
  MatrixXd dense(R, F);
  X.rows_into(0, R, dense);
  const Index k = std::min(R, F);
  VectorXd singular(k);
  MatrixXd U(R, k), Vt(k, F);
  thin_svd_serial(R, F, dense.data(), R, singular.data(), U.data(), R, Vt.data(), k);
  const VectorXd sigma = singular.head(candidates);
  return basis_from_directions(U.leftCols(candidates) * sigma.asDiagonal(), sigma);  // X v_i, as above
}

PcaBasis thin_pca(const MatrixXd& X, int max_vectors) { return thin_pca(TrainingMatrix(X), max_vectors); }

double residual_pass(const TrainingMatrix& X, const MatrixXd& A, const MatrixXd& C, int channels,
                     const MatrixXd& directions, MatrixXd* projected) {
  assert(channels >= 1 && X.rows() % channels == 0);
  assert(A.rows() == X.rows() && C.rows() == A.cols() && C.cols() == X.cols());
  assert(directions.cols() == 0 || (directions.rows() == X.cols() && projected != nullptr));
  const Index R = X.rows(), F = X.cols(), M = A.cols(), k = directions.cols();
  if (k > 0) projected->resize(R, k);
  const Index block_rows = kResidualBlockPoints * channels;
  const Index blocks = (R + block_rows - 1) / block_rows;
  std::vector<double> block_max(static_cast<size_t>(blocks), 0.0);
  const MatrixXd negated = -C;
  parallel_for_chunks(blocks, 1, [&](int64_t first, int64_t last) {
    MatrixXd E(std::min(block_rows, R), F);  // one block of the residual, in cache
    for (int64_t b = first; b < last; ++b) {
      const Index r0 = b * block_rows;
      const Index n = std::min(block_rows, R - r0);
      X.rows_into(r0, n, E);
      gemm_serial(n, M, F, A.data() + r0, A.outerStride(), negated.data(), negated.rows(), 1.0, E.data(), E.rows());
      for (Index f = 0; f < F; ++f) {
        const Eigen::Map<const MatrixXd, 0, Eigen::OuterStride<>> frame(E.col(f).data(), channels, n / channels,
                                                                         Eigen::OuterStride<>(channels));
        block_max[static_cast<size_t>(b)] =
            std::max(block_max[static_cast<size_t>(b)], frame.colwise().squaredNorm().maxCoeff());
      }
      if (k > 0) {
        gemm_serial(n, F, k, E.data(), E.rows(), directions.data(), directions.rows(), 0.0, projected->data() + r0,
                    R);
      }
    }
  });
  double largest = 0;
  for (double m : block_max) largest = std::max(largest, m);
  return std::sqrt(largest);
}

VectorXd max_point_error_per_frame(const MatrixXd& residual, int channels) {
  assert(channels >= 1 && residual.rows() % channels == 0);
  const Index points = residual.rows() / channels;
  VectorXd errors = VectorXd::Zero(residual.cols());
  if (points == 0) return errors;
  for (Index f = 0; f < residual.cols(); ++f) {
    // A column of a column-major matrix is contiguous: view it as D × N, one point per column.
    const Eigen::Map<const MatrixXd> frame(residual.col(f).data(), channels, points);
    errors(f) = std::sqrt(frame.colwise().squaredNorm().maxCoeff());
  }
  return errors;
}

double max_point_error(const MatrixXd& residual, int channels) {
  const VectorXd errors = max_point_error_per_frame(residual, channels);
  return errors.size() == 0 ? 0.0 : errors.maxCoeff();
}

double residual_pass(const MatrixXd& X, const MatrixXd& A, const MatrixXd& C, int channels,
                     const MatrixXd& directions, MatrixXd* projected) {
  return residual_pass(TrainingMatrix(X), A, C, channels, directions, projected);
}

int choose_basis_size(const TrainingMatrix& X, const PcaBasis& pca, int channels, double point_error_bound,
                      int max_basis) {
  assert(channels >= 1 && X.rows() % channels == 0);
  assert(pca.basis.rows() == X.rows());
  assert(point_error_bound >= 0.0 && max_basis >= 1);
  const int limit = static_cast<int>(std::min<Index>(max_basis, pca.basis.cols()));
  if (limit == 0) return 0;

  // E_{m+1} = E_m − a_m c_m with c_m = a_mᵀ X, the coefficients of every frame formed once over
  // all rows; with orthonormal a's (thin_pca re-orthonormalises them to ~1e-15) this equals
  // X − A_{m+1} A_{m+1}ᵀ X. Each block of points then runs its own rows, and largest(m) is the
  // worst point over the blocks after m + 1 directions. In stages of directions, so that the
  // search ends near the answer rather than at `limit`: each stage starts every block afresh at
  // E = X − A_{m0} C_{m0} (one product), then steps through the stage's directions.
  const Index R = X.rows(), F = X.cols();
  const auto A = pca.basis.leftCols(limit);  // no copy: at studio sizes it is a gigabyte
  const MatrixXd coefficients = X.transposed_times(A);  // limit × F
  const MatrixXd negated = -coefficients;
  // A block small enough to stay in a core's cache through a stage (~256 KB).
  const Index block_points = std::max<Index>(1, (Index{1} << 15) / (F * channels));
  const Index block_rows = block_points * channels;
  const Index blocks = (R + block_rows - 1) / block_rows;
  const double bound_squared = point_error_bound * point_error_bound;
  for (int m0 = 0; m0 < limit;) {
    const int m1 = std::min(limit, m0 + std::max(16, m0 / 2));
    MatrixXd largest = MatrixXd::Zero(m1 - m0, blocks);  // squared
    parallel_for_chunks(blocks, 1, [&](int64_t first, int64_t last) {
      MatrixXd E(std::min(block_rows, R), F);
      for (int64_t b = first; b < last; ++b) {
        const Index r0 = b * block_rows;
        const Index n = std::min(block_rows, R - r0);
        X.rows_into(r0, n, E);
        if (m0 > 0) {
          gemm_serial(n, m0, F, A.data() + r0, A.outerStride(), negated.data(), negated.outerStride(), 1.0, E.data(),
                      E.outerStride());
        }
        for (int m = m0; m < m1; ++m) {
          E.topRows(n).noalias() -= A.col(m).segment(r0, n) * coefficients.row(m);
          double worst = 0;
          for (Index f = 0; f < F; ++f) {
            const Eigen::Map<const MatrixXd, 0, Eigen::OuterStride<>> frame(E.col(f).data(), channels, n / channels,
                                                                             Eigen::OuterStride<>(channels));
            worst = std::max(worst, frame.colwise().squaredNorm().maxCoeff());
          }
          largest(m - m0, b) = worst;
        }
      }
    });
    for (int m = m0; m < m1; ++m) {
      if (largest.row(m - m0).maxCoeff() <= bound_squared) return m + 1;
    }
    m0 = m1;
  }
  return limit;
}

int choose_basis_size(const MatrixXd& X, const PcaBasis& pca, int channels, double point_error_bound, int max_basis) {
  return choose_basis_size(TrainingMatrix(X), pca, channels, point_error_bound, max_basis);
}

}  // namespace animspace::pmsc
