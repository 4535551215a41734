// Kaiser's varimax rotation of a block of basis vectors.
//
// Meyer & Anderson 2006 §4 (seed 000) and 2007 §2.2 (seed 001): before key points are picked,
// the 10–20 basis vectors of the current residual are rotated by "the Varimax method [Harman
// 1976] which computes an orthogonal rotation that maximizes the ratio of the 4th moment to the
// 2nd moment of the basis vectors, a measure of locality" — it concentrates each vector on a few
// points, so its largest entry is a good key point. A rotation leaves the spanned subspace, and
// so the projection error, unchanged (seed 001 §2.1).
//
// Criterion (raw varimax, Kaiser 1958): for loadings Λ (R × k),
//   V(Λ) = Σ_j [ (1/R) Σ_i Λ_ij⁴ − ((1/R) Σ_i Λ_ij²)² ],
// the sum over columns of the variance of the squared entries; V >= 0, even in each entry, and
// invariant under permutations and sign changes of the columns.
//
// Algorithm: Kaiser's own, sweeps of pairwise plane rotations (Kaiser 1958; Harman 1976):
// each pair of columns is turned by the angle that maximises V in their plane, which has a
// closed form, so V never decreases and no step overshoots. We prefer it to the SVD ("polar")
// iteration of R's stats::varimax (Q ← U Vᵀ from the SVD of the gradient), which converges
// slowly on loadings without clear structure (hundreds of iterations on Gaussian loadings) and
// can jump to a symmetric image of its start and stall there (two columns, Kaiser-normalised
// simple structure turned by 30°). One sweep is k(k−1)/2 plane steps of ~20·R flops each, plus
// one R × k × k product; nothing R × R.
//
// Precision: double. It runs at training time, once per key-selection iteration.
#pragma once

#include <Eigen/Core>

namespace animspace::pmsc {

// Kaiser row normalisation: rotate the rows scaled to unit length (rows of zero length stay
// zero), so that points with large motion do not dominate the criterion, then scale back.
enum class VarimaxNormalization { kNone, kKaiser };

struct VarimaxResult {
  Eigen::MatrixXd rotated;   // R × k, loadings · rotation
  Eigen::MatrixXd rotation;  // k × k, orthogonal (QᵀQ = I to ~1e-15), det = +1
  int iterations = 0;        // sweeps taken (0 for k <= 1 or all-zero loadings)
  // The maximised criterion at the loadings and at the result: the raw V(Λ) and V(ΛQ) with
  // kNone; with kKaiser, V of the row-normalised loadings before and after the rotation.
  // criterion_after >= criterion_before always.
  double criterion_before = 0.0;
  double criterion_after = 0.0;
  // The criterion's relative increase in the last sweep fell below the tolerance (true for the
  // trivial cases); false when max_iterations sweeps ran out first.
  bool converged = false;
};

// Varimax-rotates loadings (R × k; R >= 1, finite). Sweeps start from the identity and stop
// when one sweep raises the criterion by no more than `tolerance` (> 0) relative, or after
// `max_iterations` (>= 0) sweeps. The rotation is a product of plane rotations, so it is proper
// (det = +1); columns come out in no particular order and with no particular sign (both leave V
// and the subspace unchanged). k = 1 (or all-zero loadings) returns the identity.
VarimaxResult varimax(const Eigen::MatrixXd& loadings, int max_iterations = 200,
                      double tolerance = 1e-9,
                      VarimaxNormalization normalization = VarimaxNormalization::kNone);

// V(loadings) above, for loadings R × k (R >= 1); computed as the mean of (Λ_ij² − m_j)² with
// m_j the column's mean square, which avoids the cancellation of E[x⁴] − E[x²]².
double varimax_criterion(const Eigen::MatrixXd& loadings);

}  // namespace animspace::pmsc
