#include "core/pmsc/key_points.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/SVD>

#include "core/common/kernels.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/varimax.h"

namespace animspace::pmsc {

Eigen::MatrixXd gather_key_rows(const Eigen::MatrixXd& rows, const std::vector<int>& key_points, int channels) {
  return TrainingMatrix(rows).gather_rows(key_points, channels);
}

Eigen::VectorXd key_reconstruction_worst_errors(const Eigen::MatrixXd& X, const Eigen::MatrixXd& basis,
                                                const std::vector<int>& key_points, int channels) {
  assert(X.rows() == basis.rows() && channels >= 1 && X.rows() % channels == 0);
  const Eigen::MatrixXd P =
      least_squares_projection(gather_key_rows(basis, key_points, channels), kMaxConditionNumber, nullptr, nullptr);
  const Eigen::MatrixXd coordinates = P * gather_key_rows(X, key_points, channels);  // M × F
  Eigen::VectorXd worst(X.cols());
  // 32 frames of the residual at a time: 77 MB at the papers' 100k points.
  constexpr long kFramesPerBlock = 32;
  Eigen::MatrixXd residual;
  for (long first = 0; first < X.cols(); first += kFramesPerBlock) {
    const long count = std::min(kFramesPerBlock, X.cols() - first);
    residual = X.middleCols(first, count);
    residual.noalias() -= basis * coordinates.middleCols(first, count);
    worst.segment(first, count) = max_point_error_per_frame(residual, channels);
  }
  return worst;
}

namespace {

// Eqs. 6 and 7 on one rotated basis vector v (R values, D per point): i maximises ‖v_i‖, j
// minimises v_i·v_k, both among candidates not already chosen. Returns how many were added.
int choose_from_vector(const Eigen::VectorXd& v, int channels, int candidate_count, std::vector<char>& chosen,
                       std::vector<int>& keys) {
  const long D = channels;
  int best_i = -1;
  double best_norm = -1;
  for (int k = 0; k < candidate_count; ++k) {
    if (chosen[static_cast<size_t>(k)]) continue;
    const double norm = v.segment(k * D, D).squaredNorm();
    if (norm > best_norm) {
      best_norm = norm;
      best_i = k;
    }
  }
  if (best_i < 0 || best_norm <= 0) return 0;
  chosen[static_cast<size_t>(best_i)] = 1;
  keys.push_back(best_i);

  const Eigen::VectorXd vi = v.segment(best_i * D, D);
  int best_j = -1;
  double most_negative = 0;  // only a genuinely anti-correlated point qualifies
  for (int k = 0; k < candidate_count; ++k) {
    if (chosen[static_cast<size_t>(k)]) continue;
    const double dot = vi.dot(v.segment(k * D, D));
    if (dot < most_negative) {
      most_negative = dot;
      best_j = k;
    }
  }
  if (best_j < 0) return 1;
  chosen[static_cast<size_t>(best_j)] = 1;
  keys.push_back(best_j);
  return 2;
}

}  // namespace

Result<KeyPointSelection> select_key_points(const Eigen::MatrixXd& T, const Eigen::MatrixXd& basis,
                                            const KeyPointOptions& options) {
  return select_key_points(TrainingMatrix(T), basis, options);
}

Result<KeyPointSelection> select_key_points(const TrainingMatrix& T, const Eigen::MatrixXd& basis,
                                            const KeyPointOptions& o) {
  const int D = o.channel_count;
  if (D < 1 || T.rows() % D != 0) {
    return make_error(ErrorCode::kInvalidArgument, "channels: " + std::to_string(D) + " does not divide the " +
                                                       std::to_string(T.rows()) + " rows of the training matrix");
  }
  const int N = static_cast<int>(T.rows() / D);
  const int candidates = o.candidate_count > 0 ? o.candidate_count : N;
  if (candidates > N) {
    return make_error(ErrorCode::kInvalidArgument, "candidate_count " + std::to_string(candidates) +
                                                       " exceeds the " + std::to_string(N) + " points");
  }
  if (basis.rows() != T.rows() || basis.cols() < 1) {
    return make_error(ErrorCode::kInvalidArgument, "basis must have " + std::to_string(T.rows()) + " rows");
  }
  if (o.block_size < 1) return make_error(ErrorCode::kInvalidArgument, "block_size must be ≥ 1");
  if (!(o.error_bound >= 0)) return make_error(ErrorCode::kInvalidArgument, "error_bound must be ≥ 0");

  KeyPointSelection out;
  std::vector<char> chosen(static_cast<size_t>(N), 0);
  for (int seed : o.seed_points) {
    if (seed < 0 || seed >= candidates) {
      return make_error(ErrorCode::kInvalidArgument, "seed point " + std::to_string(seed) + " is outside [0, " +
                                                         std::to_string(candidates) + ")");
    }
    if (chosen[static_cast<size_t>(seed)]) continue;  // a fiducial listed twice counts once
    chosen[static_cast<size_t>(seed)] = 1;
    out.key_points.push_back(seed);
  }

  // The residual of the KPSA reconstruction of T with the current keys is E = T − A·C, with C =
  // P·T_key (M × F) the keys' coordinates of every frame. Each iteration needs its largest point
  // error and the leading directions of its Gram matrix EᵀE; forming EᵀE from E cost R·F² flops
  // an iteration (31 GFlop at the papers' 100k illumination points), but
  //   EᵀE = TᵀT − Hᵀ·C − Cᵀ·H + Cᵀ·(AᵀA)·C,   H = AᵀT,
  // from products formed once, costs O(M·F²). (Rounding in TᵀT is ~eps·‖T‖², far below the
  // residual's energy whenever the keys are worth choosing; the σ_i and the basis are still
  // measured on E itself, by residual_pass.)
  const long R = T.rows(), F = T.cols(), M = basis.cols();
  const Eigen::MatrixXd gram_T = T.gram();
  const Eigen::MatrixXd H = T.transposed_times(basis);
  Eigen::MatrixXd gram_A = Eigen::MatrixXd::Zero(M, M);
  gram_lower_serial(R, M, basis.data(), basis.outerStride(), gram_A.data(), M);
  gram_A = gram_A.selfadjointView<Eigen::Lower>();

  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(M, F);
  const auto update_coordinates = [&](const std::vector<int>& keys) {
    const Eigen::MatrixXd P = least_squares_projection(gather_key_rows(basis, keys, D), kMaxConditionNumber, nullptr, nullptr);
    C.noalias() = P * T.gather_rows(keys, D);
  };

  if (!out.key_points.empty()) update_coordinates(out.key_points);
  Eigen::MatrixXd directions;
  for (int iteration = 0; iteration < o.max_iterations; ++iteration) {
    const Eigen::MatrixXd HtC = H.transpose() * C;
    Eigen::MatrixXd gram_E = gram_T - HtC - HtC.transpose();
    gram_E.noalias() += C.transpose() * (gram_A * C);
    const Eigen::MatrixXd V = leading_gram_eigenvectors(gram_E, static_cast<int>(std::min<long>(o.block_size, R)));
    const double max_residual = residual_pass(T, basis, C, D, V, &directions);
    if (!out.key_points.empty()) out.max_residual.push_back(max_residual);
    if (!out.key_points.empty() && max_residual <= o.error_bound) {
      out.converged = true;
      break;
    }
    if (static_cast<int>(out.key_points.size()) >= o.max_key_points) break;

    // A block of basis vectors from the residual, localised by Varimax.
    const PcaBasis block = pca_from_directions(directions);
    if (block.basis.cols() == 0) break;  // the residual is numerically zero
    // Only the argmax points of the rotated vectors are used, so a loose tolerance suffices.
    const VarimaxResult rotated = varimax(block.basis, 100, 1e-6);

    int added = 0;
    for (long c = 0; c < rotated.rotated.cols(); ++c) {
      if (static_cast<int>(out.key_points.size()) >= o.max_key_points) break;
      added += choose_from_vector(rotated.rotated.col(c), D, candidates, chosen, out.key_points);
    }
    if (static_cast<int>(out.key_points.size()) > o.max_key_points) out.key_points.resize(static_cast<size_t>(o.max_key_points));
    if (added == 0) break;  // every candidate is already a key
    report_progress(o.progress, "key points", static_cast<int64_t>(out.key_points.size()), o.max_key_points);
    update_coordinates(out.key_points);
  }
  if (out.max_residual.empty()) out.max_residual.push_back(residual_pass(T, basis, C, D));
  return out;
}

}  // namespace animspace::pmsc
