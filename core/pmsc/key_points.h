// Key point selection (Meyer & Anderson 2006 §4; 2007 §2.2).
//
//   keyPoints = fiducial seeds
//   resid = T
//   until max residual ≤ bound (or the key budget is spent):
//     block of 10–20 basis vectors from resid (PCA)
//     Varimax-rotate the block (localises each vector)
//     from each rotated vector v: i = argmax_k ‖v_k‖, j = argmin_k v_i·v_k (eqs. 6, 7),
//       skipping points already chosen
//     T̂ = KPSA reconstruction of T with the current keys and the runtime basis
//     resid = T − T̂
//
// The block vectors of later iterations are discarded: reconstruction always uses the runtime
// basis computed from the initial training matrix (2007 §2.2, last paragraph).
#pragma once

#include <algorithm>
#include <vector>

#include <Eigen/Core>

#include "core/common/progress.h"
#include "core/common/result.h"
#include "core/pmsc/training_matrix.h"

namespace animspace::pmsc {

// The most keys any model is given, as a fraction of its control points (issues #51, #52): a
// client poses every key, and a key budget past a few percent of the points is no longer the
// papers' bargain (2006 §6: 170 keys for 2,986 points, 6%).
inline constexpr double kMaxKeyFraction = 0.08;
// That ceiling for `points` control points (at least one key).
inline int max_key_count(long points) {
  return std::max(1, static_cast<int>(kMaxKeyFraction * static_cast<double>(points)));
}

struct KeyPointOptions {
  int channel_count = 3;  // D
  // Basis vectors per block, 10–20 in the papers.
  int block_size = 12;
  // Stop when every point of every training frame is reconstructed within this distance
  // (Euclidean over the D channels, model units).
  double error_bound = 0;
  int max_key_points = 200;
  int max_iterations = 200;
  // Points chosen first (designer fiducials, a sparse grid), in order.
  std::vector<int> seed_points;
  // Keys are chosen among points [0, candidate_count): the control points of a cross-PMSC
  // model, which come first in the stacked training matrix. 0 means all points.
  int candidate_count = 0;
  // Keys chosen so far, of max_key_points.
  ProgressCallback progress = {};
};

struct KeyPointSelection {
  std::vector<int> key_points;          // seeds first, then in order of selection
  std::vector<double> max_residual;     // after each iteration (model units)
  bool converged = false;               // max residual ≤ error_bound
};

// T: R × F mean-centred training matrix (R = points·D, point-major rows); basis: R × M runtime
// basis from T. Errors: kInvalidArgument naming the option for bad sizes or seeds outside the
// candidates.
// T may be a TrainingMatrix over the frames themselves (training_matrix.h): the selection holds
// nothing the size of the frames, only the basis and a block of the residual per core.
Result<KeyPointSelection> select_key_points(const TrainingMatrix& T, const Eigen::MatrixXd& basis,
                                            const KeyPointOptions& options);
Result<KeyPointSelection> select_key_points(const Eigen::MatrixXd& T, const Eigen::MatrixXd& basis,
                                            const KeyPointOptions& options);

// Each frame's worst point as its key rows alone reconstruct it, max_i ‖x_i − (A P x_key)_i‖ with
// P the runtime's least-squares projection of A's key rows (pmsc_model.h): X is R × F frames less
// the basis's mean, A = `basis` (R × M). What the held-out key budget measures (train.h,
// held_out_key_slack) on frames the keys were not chosen on. Frames are reconstructed a few at a
// time, so nothing R × F is formed.
Eigen::VectorXd key_reconstruction_worst_errors(const Eigen::MatrixXd& X, const Eigen::MatrixXd& basis,
                                                const std::vector<int>& key_points, int channels);

// Rows of the key points: (K·D) × cols, gathered from point-major `rows`.
Eigen::MatrixXd gather_key_rows(const Eigen::MatrixXd& rows, const std::vector<int>& key_points, int channels);

}  // namespace animspace::pmsc
