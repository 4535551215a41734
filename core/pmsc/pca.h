// Thin PCA of a tall training matrix and the choice of the subspace dimension M.
//
// Meyer & Anderson 2006, "Key Point Subspace Acceleration and Soft Caching", §3 (seed 000) and
// Meyer & Anderson 2007 §2.1 (seed 001): the subspace basis vectors a_i are the left singular
// vectors of the mean-centred training matrix Q (EOF analysis), in order of decreasing singular
// value, and M "is chosen such that the subspace projection error of the training set is
// acceptably small".
//
// Layout of a training matrix X (R × F): R = N·D rows, point-major (row p·D + c holds channel c
// of point p; D = 3 for positions), one column per training frame, mean-centred by the caller.
// In our use F (frames, tens to a few hundred) is much smaller than R (e.g. 30006 × 88).
//
// Precision: double throughout. These run at training time, once per model or once per
// key-selection iteration, where accuracy of the subspace matters more than speed; the points
// that fill X arrive as float32 and are promoted.
#pragma once

#include <Eigen/Core>

#include "core/pmsc/training_matrix.h"

namespace animspace::pmsc {

// σ_i below this fraction of σ_0 are treated as zero: thin_pca keeps only directions with
// σ_i > kRelativeSingularValueFloor · σ_0. See pca.cpp for why 1e-7.
inline constexpr double kRelativeSingularValueFloor = 1e-7;

// A thin PCA basis of a training matrix X (R × F).
struct PcaBasis {
  // R × k, orthonormal columns a_0 … a_{k-1} (basisᵀ·basis = I to ~1e-15), ordered by
  // decreasing singular value. Sign convention: each column's entry of largest magnitude (the
  // first such entry on ties) is positive, so equal inputs give equal bases and X and -X give
  // the same basis.
  Eigen::MatrixXd basis;
  // k, the singular values σ_i of X belonging to the columns, descending, all > 0.
  Eigen::VectorXd singular_values;
};

// The leading left singular vectors of X (R × F): k = min(max_vectors, numerical rank of X)
// columns, where the numerical rank counts σ_i > kRelativeSingularValueFloor · σ_0. X all zero
// (or with no rows or columns) gives k = 0: an R × 0 basis. max_vectors >= 0.
//
// For R > F it eigen-decomposes the F × F Gram matrix XᵀX = V Λ Vᵀ and forms a_i = X v_i / σ_i
// with σ_i = ‖X v_i‖, then re-orthonormalises the columns once. Cost: R·F²/2 (Gram) + R·F·k
// (X V) + 2·R·k² (re-orthonormalisation) flops, plus O(F³); memory R·k + F². For F >= R it
// takes the thin U of a bidiagonal divide-and-conquer SVD of X instead. X may be a TrainingMatrix
// over the frames themselves (training_matrix.h): then the only R-sized storage is the R × k
// result (the directions are scaled, ordered and re-orthonormalised in place).
PcaBasis thin_pca(const TrainingMatrix& X, int max_vectors);
PcaBasis thin_pca(const Eigen::MatrixXd& X, int max_vectors);

// thin_pca in two halves, for a caller that has XᵀX without forming it from X (key_points.cpp:
// the residual's Gram matrix from products computed once):
//   leading_gram_eigenvectors  V, the eigenvectors of the F × F Gram matrix XᵀX (lower triangle
//                              read) with the min(count, F) largest eigenvalues, descending;
//   pca_from_directions        from U = X V (R × k): σ_i = ‖X v_i‖ and the basis thin_pca returns
//                              (order by σ, floor, a_i = X v_i / σ_i, re-orthonormalised, signs).
Eigen::MatrixXd leading_gram_eigenvectors(const Eigen::MatrixXd& gram, int count);
PcaBasis pca_from_directions(Eigen::MatrixXd directions);

// Points per row block of residual_pass: a block of the residual (kResidualBlockPoints · D rows
// by F frames) stays in cache between its product and its reads (2.5 MB for D = 3, F = 324).
inline constexpr long kResidualBlockPoints = 1024;

// One pass over the residual E = X − A·C (X: R × F, A: R × M, C: M × F) without forming it
// whole: returns max_point_error(E, channels) and, when `directions` (F × k) has columns, writes
// E·directions (R × k) to `projected`. Blocks of kResidualBlockPoints points run on all cores;
// the blocks do not depend on the thread count, so neither does any bit of the result. For the
// key selection's residual at the papers' 100k illumination points, 777 MB never written.
double residual_pass(const TrainingMatrix& X, const Eigen::MatrixXd& A, const Eigen::MatrixXd& C, int channels,
                     const Eigen::MatrixXd& directions = Eigen::MatrixXd(), Eigen::MatrixXd* projected = nullptr);
double residual_pass(const Eigen::MatrixXd& X, const Eigen::MatrixXd& A, const Eigen::MatrixXd& C, int channels,
                     const Eigen::MatrixXd& directions = Eigen::MatrixXd(), Eigen::MatrixXd* projected = nullptr);

// The subspace dimension M (seed 001 §2.1): the smallest M in 1 … min(max_basis,
// pca.basis.cols()) such that the projection residual X − A_M A_Mᵀ X (A_M = the first M basis
// columns) has, at every point and frame, Euclidean norm ≤ point_error_bound (the norm over the
// point's `channels` consecutive rows; same units as X). If no M qualifies, the largest allowed
// value; 0 only when the basis is empty.
//
// X: R × F, the matrix `pca` was computed from (or any matrix with R rows); channels >= 1
// divides R; point_error_bound >= 0; max_basis >= 1. Incremental: the residual loses one rank-1
// term a_m (a_mᵀ E) per step, so the cost is ~5·R·F flops per candidate M (O(M·R·F) in all,
// not O(M²·R·F)). A point's residual depends on its own rows only, so the pass runs a block of
// rows at a time, each block as far as it must (memory: one block, never a copy of X).
int choose_basis_size(const TrainingMatrix& X, const PcaBasis& pca, int channels, double point_error_bound,
                      int max_basis);
int choose_basis_size(const Eigen::MatrixXd& X, const PcaBasis& pca, int channels,
                      double point_error_bound, int max_basis);

// F: for each column (frame) f of residual (R × F), max over points p of ‖residual(p·D … p·D+D-1,
// f)‖₂ with D = channels (>= 1, divides R). Zero for R = 0.
Eigen::VectorXd max_point_error_per_frame(const Eigen::MatrixXd& residual, int channels);

// The largest per-point Euclidean error over all frames and points of residual (R × F), as
// above; 0 for an empty matrix.
double max_point_error(const Eigen::MatrixXd& residual, int channels);

}  // namespace animspace::pmsc
