#include "core/pmsc/train.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <atomic>
#include <cmath>
#include <mutex>
#include <numeric>
#include <string>

#include <Eigen/Eigenvalues>

#include "core/common/kernels.h"
#include "core/common/parallel.h"
#include "core/common/timing.h"

#include "core/pmsc/articulated.h"
#include "core/pmsc/check_points.h"
#include "core/pmsc/key_points.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/relative_point_errors.h"
#include "core/pmsc/regions.h"
#include "core/pmsc/subspace.h"
#include "core/geometry/rigid_fit.h"

namespace animspace::pmsc {
namespace {

// Held-out poses per reconstruction in the calibration: the batched product reads the basis once
// per batch (from kBlasGemmMinColumns poses on it beats a product per pose, kernels.h), and 32
// keep a worker's points at 38 MB for the papers' 100k points.
constexpr long kCalibrationBatch = 32;

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

Eigen::Map<const Eigen::Matrix3Xd> points_of(const Eigen::VectorXd& frame, long first_point, long count) {
  return Eigen::Map<const Eigen::Matrix3Xd>(frame.data() + 3 * first_point, 3, count);
}

// Generalised Procrustes on the control points: align every frame to the first, then twice to
// the mean of the aligned frames. Returns per-frame transforms aligned → world.
std::vector<geometry::RigidTransform> rigid_motion_per_frame(const Eigen::MatrixXd& T, long control_points) {
  const long F = T.cols();
  std::vector<geometry::RigidTransform> transforms(static_cast<size_t>(F));
  Eigen::Matrix3Xd reference = points_of(T.col(0), 0, control_points);
  for (int pass = 0; pass < 3; ++pass) {
    Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, control_points);
    for (long f = 0; f < F; ++f) {
      const Eigen::VectorXd frame = T.col(f);
      const auto world = points_of(frame, 0, control_points);
      transforms[static_cast<size_t>(f)] = geometry::fit_rigid(reference, world);
      const geometry::RigidTransform inverse = transforms[static_cast<size_t>(f)].inverse();
      sum += (inverse.rotation * world).colwise() + inverse.translation;
    }
    reference = sum / static_cast<double>(F);
  }
  return transforms;
}

void apply_inverse(const geometry::RigidTransform& to_world, Eigen::Ref<Eigen::VectorXd> frame) {
  const geometry::RigidTransform inverse = to_world.inverse();
  Eigen::Map<Eigen::Matrix3Xd> points(frame.data(), 3, frame.size() / 3);
  points = (inverse.rotation * points).colwise() + inverse.translation;
}

// Seeds of a sparse grid: the point nearest each occupied cell's centre.
std::vector<int> grid_seeds(const PointMatrix& positions, int cells) {
  const Eigen::RowVector3f lo = positions.colwise().minCoeff();
  const Eigen::RowVector3f hi = positions.colwise().maxCoeff();
  const Eigen::RowVector3f size = (hi - lo).cwiseMax(1e-20f);
  std::vector<int> best(static_cast<size_t>(cells * cells * cells), -1);
  std::vector<float> best_distance(best.size(), 0);
  for (long i = 0; i < positions.rows(); ++i) {
    const Eigen::RowVector3f u = (positions.row(i) - lo).cwiseQuotient(size) * static_cast<float>(cells);
    int cell[3];
    for (int a = 0; a < 3; ++a) cell[a] = std::clamp(static_cast<int>(u(a)), 0, cells - 1);
    const size_t index = static_cast<size_t>((cell[0] * cells + cell[1]) * cells + cell[2]);
    Eigen::RowVector3f centre;
    for (int a = 0; a < 3; ++a) centre(a) = static_cast<float>(cell[a]) + 0.5f;
    const float distance = (u - centre).squaredNorm();
    if (best[index] < 0 || distance < best_distance[index]) {
      best[index] = static_cast<int>(i);
      best_distance[index] = distance;
    }
  }
  std::vector<int> seeds;
  for (int b : best) {
    if (b >= 0) seeds.push_back(b);
  }
  return seeds;
}

// A subspace as training makes it: the served one in double; a calibration fold's in float, the
// precision its model serves it in (issue #53: two workers' double fold bases were 1.2 GB at 186k
// points), its mean and the key rows taken in double all the same.
template <typename Scalar>
struct SubspaceBasis {
  Eigen::VectorXd mean;                                             // R
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> basis;      // R × M
  Eigen::VectorXd sigma;                                            // M
};
using TrainingBasis = SubspaceBasis<double>;
using FoldBasis = SubspaceBasis<float>;

// The subspace of the frames `kept` (columns of T) for a calibration fold, through the Gram
// matrix G = TᵀT of all frames: the fold's centred Gram matrix is G restricted to `kept` and
// double-centred, its leading eigenvectors v_k give a_k = X v_k / σ_k (X the centred fold, the
// same identity thin_pca uses), and every product runs on T itself — no R × F copy per fold,
// which on crane was most of the calibration's time. Basis signs are arbitrary (the projection
// does not see them); directions with σ_k ≤ kRelativeSingularValueFloor · σ_0 are dropped.
struct FoldWeights {
  Eigen::MatrixXd W;             // F × count: basis = T W
  Eigen::VectorXd mean_weights;  // F: mean = T mean_weights
  Eigen::VectorXd sigma;         // count
};

FoldWeights fold_weights(const Eigen::MatrixXd& G, long F, const std::vector<long>& kept, int M) {
  const long s = static_cast<long>(kept.size());
  Eigen::MatrixXd C(s, s);
  for (long i = 0; i < s; ++i) {
    for (long j = 0; j < s; ++j) C(i, j) = G(kept[static_cast<size_t>(i)], kept[static_cast<size_t>(j)]);
  }
  const Eigen::VectorXd row_means = C.rowwise().mean();
  const double total_mean = row_means.mean();
  C.colwise() -= row_means;
  C.rowwise() -= row_means.transpose();
  C.array() += total_mean;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(C);  // ascending eigenvalues
  const double largest = std::max(eigen.eigenvalues()(s - 1), 0.0);
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(F, M);  // basis = T W
  Eigen::VectorXd sigma(M);
  long count = 0;
  for (; count < M && count < s; ++count) {
    const double lambda = eigen.eigenvalues()(s - 1 - count);
    if (!(lambda > 0) || std::sqrt(lambda) <= kRelativeSingularValueFloor * std::sqrt(largest)) break;
    sigma(count) = std::sqrt(lambda);
    const Eigen::VectorXd v = eigen.eigenvectors().col(s - 1 - count);
    const double v_mean = v.mean();  // X v = T_kept (v − mean(v) 1)
    for (long i = 0; i < s; ++i) W(kept[static_cast<size_t>(i)], count) = (v(i) - v_mean) / sigma(count);
  }
  FoldWeights out;
  out.mean_weights = Eigen::VectorXd::Zero(F);
  for (long f : kept) out.mean_weights(f) = 1.0 / static_cast<double>(s);
  out.W = W.leftCols(count);
  out.sigma = sigma.head(count);
  return out;
}

// Writes into `out`, whose storage a calibration worker reuses from one fold to the next: at the
// papers' 100k illumination points a fold's basis is 300k × 136 doubles, and faulting in fresh
// pages for it, its linear copy and the model's float copy in every fold was a third of the
// calibration's profile.
// G may be the Gram matrix of X or of X less any one vector: the double-centred fold Gram and
// W (whose columns sum to zero over `kept`) do not see it. So is X's offset, but for the mean.
template <typename Scalar>
void fold_subspace(const TrainingMatrix& X, const Eigen::MatrixXd& G, const std::vector<long>& kept, int M,
                   SubspaceBasis<Scalar>& out) {
  const FoldWeights weights = fold_weights(G, X.cols(), kept, M);
  // The fold's mean, T·mean_weights: its kept columns' average, read column by column.
  out.mean = Eigen::VectorXd::Zero(X.rows());
  for (long f : kept) out.mean += X.col(f);
  out.mean /= static_cast<double>(kept.size());
  if (X.offset().size() > 0) out.mean += X.offset();
  // The R × F by F × M product through the dispatched kernel (kernels.h): OpenBLAS's dgemm took
  // 0.07 s against Eigen/SSE2's 0.38 s for the 20,000-point Cornell box (60,000 × 144 × 100),
  // once per calibration fold (issue #38 item 3). out.basis keeps its storage when the size
  // repeats.
  X.times(weights.W, out.basis);
  out.sigma = weights.sigma;
}

// Issue #38 item 3: the held-out projection error of every basis size 0 … M_max, through the Gram
// matrix alone. For a fold (its mean μ = T m, basis A = T W) and a held-out frame x = T e_f, the
// coefficients are c = Aᵀ(x − μ) = Wᵀ(G e_f − G m) and, A being orthonormal, the residual of the
// first k directions is ‖x − μ‖² − Σ_{i<k} c_i² with ‖x − μ‖² = G_ff − 2 mᵀG e_f + mᵀG m: O(F²·M)
// per fold, no pass over the R rows. (The subtraction loses what rounding left in G, ~1e-16 of
// ‖x‖², i.e. relative RMS errors below ~1e-8 of the frame's norm are not resolved; no data set's
// noise is that small.) Returns, per basis size k, the held-out residual energy summed over every
// held-out frame of every set, and in `centred_energy` the sum of ‖x − μ‖².
Eigen::VectorXd held_out_projection_curve(const Eigen::MatrixXd& G, const std::vector<std::vector<long>>& held_out,
                                          const std::vector<std::vector<long>>& kept, int M_max,
                                          double& centred_energy) {
  const long F = G.cols();
  Eigen::VectorXd residual = Eigen::VectorXd::Zero(M_max + 1);
  centred_energy = 0;
  for (size_t set = 0; set < held_out.size(); ++set) {
    const int fold_basis = static_cast<int>(std::min<long>(M_max, static_cast<long>(kept[set].size()) - 1));
    if (fold_basis < 1) continue;
    const FoldWeights w = fold_weights(G, F, kept[set], fold_basis);
    const Eigen::VectorXd G_mean = G * w.mean_weights;
    const double mean_energy = w.mean_weights.dot(G_mean);
    for (long f : held_out[set]) {
      const double energy = std::max(0.0, G(f, f) - 2 * G_mean(f) + mean_energy);
      const Eigen::VectorXd c = w.W.transpose() * (G.col(f) - G_mean);
      centred_energy += energy;
      double left = energy;
      residual(0) += left;
      for (int k = 1; k <= M_max; ++k) {
        if (k <= c.size()) left = std::max(0.0, left - c(k - 1) * c(k - 1));
        residual(k) += left;
      }
    }
  }
  return residual;
}

// The smallest size k ≥ first whose held-out relative RMS error rms[k] is within (1 + slack) of
// the best size's ≥ first: how many directions are worth their cost, for the linear basis (issue
// #38 item 3) and for the articulated kind's residual components (issue #51).
int smallest_within_slack(const std::vector<double>& rms, int first, double slack) {
  const double best = *std::min_element(rms.begin() + first, rms.end());
  for (size_t k = static_cast<size_t>(first); k < rms.size(); ++k) {
    if (rms[k] <= (1 + slack) * best) return static_cast<int>(k);
  }
  return static_cast<int>(rms.size()) - 1;
}

// The direction a relative-tolerance model adds to an affine subspace (PmscModel::
// relative_tolerance): the mean's component orthogonal to the basis (orthonormal, as PCA and
// fold_subspace give it), normalised (twice Gram–Schmidt), or an empty vector when the mean is
// already in the span. The basis and this direction span the affine subspace with one more
// dimension, through the origin, so s·keys then give exactly s·f̂. O(R·M): a QR of every fold's
// R × (M + 1) rows doubled the calibration's time on the Cornell box.
template <typename Scalar>
Eigen::VectorXd mean_direction(const SubspaceBasis<Scalar>& s) {
  // A block of rows at a time, so that a float basis is never promoted whole.
  const long R = s.basis.rows(), block = TrainingMatrix::kBlockRows;
  Eigen::VectorXd direction = s.mean;
  for (int pass = 0; pass < 2; ++pass) {
    Eigen::VectorXd coefficients = Eigen::VectorXd::Zero(s.basis.cols());
    for (long r0 = 0; r0 < R; r0 += block) {
      const long n = std::min(block, R - r0);
      coefficients.noalias() += s.basis.middleRows(r0, n).template cast<double>().transpose() * direction.segment(r0, n);
    }
    for (long r0 = 0; r0 < R; r0 += block) {
      const long n = std::min(block, R - r0);
      direction.segment(r0, n).noalias() -= s.basis.middleRows(r0, n).template cast<double>() * coefficients;
    }
  }
  const double norm = direction.norm();
  if (!(norm > 1e-9 * s.mean.norm())) return Eigen::VectorXd();
  return direction / norm;
}

// The key rows of a subspace (mean, basis, and the relative-tolerance model's extra column when
// `extra` has rows) into a runtime model, then its projection.
template <typename Scalar>
Status place_keys(const Eigen::VectorXd& mean, const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>& basis,
                  const Eigen::VectorXd& extra, const std::vector<int>& keys, PmscModel& m) {
  const long D = m.channel_count;
  const long M_affine = basis.cols();
  const long M = M_affine + (extra.size() > 0 ? 1 : 0);
  m.key_points = keys;
  const long K = static_cast<long>(keys.size());
  m.key_mean.resize(K * D);
  m.key_basis.resize(K * D, M);
  for (long k = 0; k < K; ++k) {
    const long row = static_cast<long>(keys[static_cast<size_t>(k)]) * D;
    if (m.relative_tolerance) {
      m.key_mean.segment(k * D, D).setZero();
    } else {
      m.key_mean.segment(k * D, D) = mean.segment(row, D);
    }
    m.key_basis.block(k * D, 0, D, M_affine) = basis.middleRows(row, D).template cast<double>();
    if (M > M_affine) m.key_basis.block(k * D, M_affine, D, 1) = extra.segment(row, D);
  }
  return prepare_projection(m);
}

// Copies the output rows and the key rows of a subspace into a runtime model and prepares it.
// A relative-tolerance model is served linear: mean 0 and the mean's direction as one more basis
// column. Written straight into the model's own storage (the calibration's workers reuse it).
template <typename Scalar>
Status assemble(const SubspaceBasis<Scalar>& affine, long control_rows, bool cross, const std::vector<int>& keys,
                PmscModel& m) {
  const Eigen::VectorXd extra = m.relative_tolerance ? mean_direction(affine) : Eigen::VectorXd();
  const long M_affine = affine.basis.cols();
  const long M = M_affine + (extra.size() > 0 ? 1 : 0);
  const long output_first = cross ? control_rows : 0;
  const long output_rows = affine.mean.size() - output_first;
  if (m.relative_tolerance) {
    m.mean.setZero(output_rows);
  } else {
    m.mean = affine.mean.segment(output_first, output_rows).template cast<float>();
  }
  m.basis.resize(output_rows, M);
  m.basis.leftCols(M_affine) = affine.basis.middleRows(output_first, output_rows).template cast<float>();
  if (M > M_affine) m.basis.col(M_affine) = extra.segment(output_first, output_rows).cast<float>();
  return place_keys(affine.mean, affine.basis, extra, keys, m);
}

// The held-out sets of the calibration (and of the held-out rules for M and for r): every
// `folds`-th frame, the same trained on half the frames, and blocks of consecutive frames.
struct HeldOutSet {
  std::vector<long> held_out, train;
  char family = kInterleavedFold;
};
struct HeldOutSets {
  std::vector<HeldOutSet> sets;
  long block = 1;  // frames per block of the shortest block family
  // The sets without the sparse folds (trained on half a fold's frames): the held-out rules
  // measure the basis of a fold, not a sparser training.
  std::vector<std::vector<long>> held_out_frames, kept_frames;
};

// The options and frames, every rule naming the option or the data.
Status check_training_input(const FrameMatrix& control_frames, const FrameMatrix* output_frames,
                            const TrainingOptions& o) {
  const int D = o.channel_count;
  const long F = control_frames.rows();
  if (D < 1) return invalid("channels must be ≥ 1, got " + std::to_string(D));
  if (F < 2) return invalid("training needs at least 2 frames, got " + std::to_string(F));
  if (control_frames.cols() == 0 || control_frames.cols() % D != 0) {
    return invalid("frames have " + std::to_string(control_frames.cols()) + " values per frame, not a multiple of " +
                   std::to_string(D) + " channels");
  }
  if (output_frames && (output_frames->rows() != F || output_frames->cols() == 0 || output_frames->cols() % D != 0)) {
    return invalid("output frames must be " + std::to_string(F) + " frames of a multiple of " + std::to_string(D) +
                   " values");
  }
  if (!control_frames.allFinite() || (output_frames && !output_frames->allFinite())) {
    return invalid("frames hold NaN or Inf values");
  }
  if (!(o.error_bound > 0) || !std::isfinite(o.error_bound)) {
    return invalid("error_bound must be a positive distance, got " + std::to_string(o.error_bound));
  }
  if (!(o.error_tolerance > 0) || !std::isfinite(o.error_tolerance)) {
    return invalid("error_tolerance must be a positive distance, got " + std::to_string(o.error_tolerance));
  }
  if (o.basis_size < 0 || o.basis_size >= F) {
    return invalid("basis_size must be < the " + std::to_string(F) + " training frames (M < F), got " +
                   std::to_string(o.basis_size));
  }
  if (o.block_size < 1 || o.max_key_points < 1) return invalid("block_size and max_key_points must be ≥ 1");
  if (o.remove_rigid_motion && D != 3) return invalid("remove_rigid_motion needs 3 channels (positions)");
  if (o.relative_tolerance && o.remove_rigid_motion) {
    return invalid("relative_tolerance needs remove_rigid_motion off: a position has no intensity to be relative to");
  }
  if (o.blend_zone_ratio < 1) return invalid("blend_zone_ratio must be ≥ 1");
  if (!(o.false_hit_rate > 0 && o.false_hit_rate < 1)) {
    return invalid("false_hit_rate must be in (0, 1), got " + std::to_string(o.false_hit_rate));
  }
  if (o.calibration_block_frames < 0) return invalid("calibration_block_frames must be ≥ 0 (0: automatic)");
  if (o.cross_fitted_calibration != 0 && o.cross_fitted_calibration != 1) {
    return invalid("cross_fitted_calibration must be 0 or 1, got " + std::to_string(o.cross_fitted_calibration));
  }
  if (!(o.check_point_fraction >= 0 && o.check_point_fraction <= 1)) {
    return invalid("check_point_fraction must be in [0, 1], got " + std::to_string(o.check_point_fraction));
  }
  if (!(o.max_basis_fraction > 0 && o.max_basis_fraction <= 1)) return invalid("max_basis_fraction must be in (0, 1]");
  if (!(o.held_out_basis_slack >= 0) || !std::isfinite(o.held_out_basis_slack)) {
    return invalid("held_out_basis_slack must be ≥ 0 (0: off), got " + std::to_string(o.held_out_basis_slack));
  }
  if (!(o.held_out_key_slack >= 0) || !std::isfinite(o.held_out_key_slack)) {
    return invalid("held_out_key_slack must be ≥ 0 (0: the budget is max_key_points), got " +
                   std::to_string(o.held_out_key_slack));
  }
  if (o.subspace_kind == SubspaceKind::kArticulated) {
    if (o.channel_count != 3) return invalid("subspace_kind articulated needs positions (3 channels), got " + std::to_string(o.channel_count));
    if (output_frames != nullptr) return invalid("subspace_kind articulated is for one point set; cross-PMSC models are linear");
    if (o.remove_rigid_motion) {
      return invalid("subspace_kind articulated needs remove_rigid_motion off: the bones carry the rigid motion");
    }
    if (o.relative_tolerance) return invalid("subspace_kind articulated needs relative_tolerance off");
    if (o.bone_count < 0) return invalid("bone_count must be ≥ 0 (0: by rule), got " + std::to_string(o.bone_count));
    if (o.residual_components < -1) {
      return invalid("residual_components must be ≥ 0, or −1 for the held-out rule, got " +
                     std::to_string(o.residual_components));
    }
  }

  return Status::Ok();
}

HeldOutSets held_out_sets(long F, const TrainingOptions& o) {
  HeldOutSets out;
  std::vector<HeldOutSet>& sets = out.sets;
  const int folds = static_cast<int>(std::min<long>(std::max(o.calibration_folds, 2), F));
  const long block = o.calibration_block_frames > 0
                         ? o.calibration_block_frames
                         : std::max<long>(1, (F + 2 * folds - 1) / (2 * folds));  // two blocks per fold
  const auto add_set = [&](const std::vector<char>& is_held, char family, long stride) {
    HeldOutSet set;
    set.family = family;
    long kept = 0;
    for (long f = 0; f < F; ++f) {
      if (is_held[static_cast<size_t>(f)]) {
        set.held_out.push_back(f);
      } else if (kept++ % stride == 0) {
        set.train.push_back(f);
      }
    }
    if (!set.held_out.empty() && set.train.size() >= 2) sets.push_back(std::move(set));
  };
  for (int fold = 0; fold < folds; ++fold) {
    std::vector<char> is_held(static_cast<size_t>(F));
    for (long f = 0; f < F; ++f) is_held[static_cast<size_t>(f)] = f % folds == fold;
    add_set(is_held, kInterleavedFold, 1);
    add_set(is_held, kSparseFold, 2);
  }
  // Blocks of `block`, 2·block and 4·block frames (one-frame blocks would repeat the interleaved
  // folds; a length that leaves fewer than two blocks holds nothing out that others keep).
  for (long length = std::max<long>(block, 2); length <= 4 * std::max<long>(block, 1); length *= 2) {
    const long blocks = (F + length - 1) / length;
    const long block_folds = std::min<long>(folds, blocks);
    if (block_folds < 2) break;
    for (long fold = 0; fold < block_folds; ++fold) {
      std::vector<char> is_held(static_cast<size_t>(F));
      for (long f = 0; f < F; ++f) is_held[static_cast<size_t>(f)] = (f / length) % block_folds == fold;
      add_set(is_held, kBlockFold, 1);
    }
  }

  out.block = block;
  for (const HeldOutSet& set : sets) {
    if (set.family == kSparseFold) continue;
    out.held_out_frames.push_back(set.held_out);
    out.kept_frames.push_back(set.train);
  }
  return out;
}

// The served basis and what the later steps need of how it was made.
struct ChosenBasis {
  TrainingBasis subspace;
  int M = 0;
  double projection_error = 0;          // of the training frames (report)
  std::vector<double> held_out_rms;     // the linear held-out rule's curve (report)
  // Articulated (articulated.h): the skinning, and the residuals' Gram matrix, which takes the
  // place of T's in the calibration's folds.
  ArticulatedSkinning skinning;
  Eigen::MatrixXd residual_gram;
  int residual_count = 0;
  double skinning_seconds = 0;
};

// The linear kind (2007 §2.1): the leading principal components of the centred frames, as many
// as the held-out rule or the error bound asks.
// `pca` is spent: its first M directions become the basis in place (issue #53: at studio sizes
// the directions are the largest thing the PCA makes).
ChosenBasis linear_basis(const TrainingMatrix& centred, PcaBasis pca, const Eigen::MatrixXd& gram,
                         const HeldOutSets& held, int chosen_cap, const TrainingOptions& o) {
  const int D = o.channel_count;
  ChosenBasis out;
  int M = o.basis_size > 0 ? std::min<int>(o.basis_size, static_cast<int>(pca.basis.cols())) : 0;
  std::vector<double>& held_out_rms = out.held_out_rms;
  const auto& held_out_frames = held.held_out_frames;
  const auto& kept_frames = held.kept_frames;
  if (o.basis_size <= 0 && o.held_out_basis_slack > 0) {
    // Issue #38 item 3, M chosen by the accuracy it buys on frames the basis did not see: the
    // held-out frames' projection error onto each fold's first k directions, over the interleaved
    // folds (poses between training poses) and the block folds (motion the rest never saw), as a
    // relative RMS (residual energy / centred energy, both summed over every held-out frame).
    // M = the smallest k whose held-out RMS is within (1 + slack) of the best k ≤ the cap. A
    // direction the held-out frames do not share — noise of the training frames, motion of one
    // block only — lowers that error by about its share of the noise and is not worth its cost
    // in the reconstruction (time ∝ M) nor in the keys' estimate (M coefficients from K·D values).
    const int M_max = std::min<int>(chosen_cap, static_cast<int>(pca.basis.cols()));
    double centred_energy = 0;
    const Eigen::VectorXd residual =
        held_out_projection_curve(gram, held_out_frames, kept_frames, M_max, centred_energy);
    if (centred_energy > 0) {
      held_out_rms.resize(static_cast<size_t>(M_max + 1));
      for (int k = 0; k <= M_max; ++k) held_out_rms[static_cast<size_t>(k)] = std::sqrt(residual(k) / centred_energy);
      M = smallest_within_slack(held_out_rms, 1, o.held_out_basis_slack);
    }
  }
  // M from the error bound: when asked for, or when the held-out rule had no held-out energy to
  // measure (only then: at the papers' 100k illumination points its passes over the centred
  // frames cost more than the rest of the PCA).
  if (M == 0) M = choose_basis_size(centred, pca, D, 0.5 * o.error_bound, chosen_cap);
  pca.basis.conservativeResize(Eigen::NoChange, M);
  out.subspace = TrainingBasis{centred.offset(), std::move(pca.basis), pca.singular_values.head(M)};
  // The projection's error through the dispatched kernels, never forming the R × F residual.
  const Eigen::MatrixXd projection_coordinates = centred.transposed_times(out.subspace.basis);
  out.projection_error = residual_pass(centred, out.subspace.basis, projection_coordinates, D);
  out.M = M;
  return out;
}

// The articulated kind (articulated.h): the skinning columns L fitted to the frames, then the
// principal components of what they leave, as many as the held-out rule keeps.
Result<ChosenBasis> articulated_basis(const FrameMatrix& control_frames, const TrainingMatrix& T,
                                      const HeldOutSets& held, int chosen_cap, const TrainingOptions& o) {
  const int D = o.channel_count;
  const long F = T.cols();
  const long rows = T.rows();
  const auto& held_out_frames = held.held_out_frames;
  const auto& kept_frames = held.kept_frames;
  ChosenBasis out;
  const auto skinning_start = std::chrono::steady_clock::now();
  const long control_points = control_frames.cols() / D;
  const int bones = o.bone_count > 0 ? o.bone_count : default_bone_count(control_points);
  auto fitted = fit_articulated_skinning(control_frames, o.faces, bones, o.progress);
  if (!fitted) return fitted.error();
  ArticulatedSkinning& skinning = out.skinning;
  skinning = std::move(*fitted);
  out.skinning_seconds = seconds_since(skinning_start);
  Eigen::MatrixXd& residual_gram = out.residual_gram;
  residual_gram.setZero(F, F);
  gram_lower_serial(rows, F, skinning.residuals.data(), rows, residual_gram.data(), F);
  residual_gram = residual_gram.selfadjointView<Eigen::Lower>().toDenseMatrix();
  int residual_count = 0;
  // r: given, or the smallest count whose held-out projection error is within
  // kResidualHeldOutSlack of the largest count's (a component the held-out frames do not share
  // is noise of the training frames, and one more coordinate to estimate from the keys). No
  // floor on the residual's size: what the skinning leaves at the training poses is mostly its
  // weights' error, which grows with the rotation at new poses (the arm of articulated_test.cpp
  // went from under 1% to 1.25% of the diagonal at 80–120° without its residual components).
  const int residual_cap = std::min<int>(chosen_cap, static_cast<int>(F - 1));
  if (o.residual_components >= 0) {
    residual_count = std::min(o.residual_components, residual_cap);
  } else {
    double centred_energy = 0;
    const Eigen::VectorXd curve =
        held_out_projection_curve(residual_gram, held_out_frames, kept_frames, residual_cap, centred_energy);
    residual_count = residual_cap;
    if (centred_energy > 0) {
      std::vector<double> rms(static_cast<size_t>(residual_cap + 1));
      for (int k = 0; k <= residual_cap; ++k) rms[static_cast<size_t>(k)] = std::sqrt(curve(k) / centred_energy);
      residual_count = smallest_within_slack(rms, 0, kResidualHeldOutSlack);
    }
  }
  std::vector<long> every_frame(static_cast<size_t>(F));
  std::iota(every_frame.begin(), every_frame.end(), 0L);
  TrainingBasis residual;
  fold_subspace(TrainingMatrix(skinning.residuals), residual_gram, every_frame, std::max(residual_count, 1),
                residual);
  if (residual_count == 0) residual.basis.resize(rows, 0);
  residual_count = static_cast<int>(residual.basis.cols());
  out.residual_count = residual_count;
  out.subspace.mean = residual.mean;
  out.subspace.basis.resize(rows, skinning.columns.cols() + residual_count);
  out.subspace.basis << skinning.columns, residual.basis;
  out.M = static_cast<int>(out.subspace.basis.cols());
  // The residual components are orthogonal to L's columns (every frame's residual is), so the
  // projection onto [L | R] leaves what R leaves of E.
  // (Read less their mean a block at a time, not copied: the residuals are R × F in double.)
  const TrainingMatrix residual_centred = TrainingMatrix(skinning.residuals).with_offset(residual.mean);
  out.projection_error =
      residual_pass(residual_centred, residual.basis, residual_centred.transposed_times(residual.basis), D);
  return out;
}

// The key selection's options (2007 §2.2): fiducials, the optional sparse grid, and for the
// articulated kind every bone's coverage points and the key budget by rule.
Result<KeyPointOptions> key_point_options(const TrainingOptions& o, const ChosenBasis& basis, const Eigen::VectorXd& mean,
                                          long control_points, bool articulated) {
  const int D = o.channel_count;
  const int M = basis.M;
  KeyPointOptions key_options;
  key_options.channel_count = D;
  key_options.block_size = o.block_size;
  key_options.error_bound = o.error_bound;
  key_options.max_key_points = o.max_key_points;
  key_options.candidate_count = static_cast<int>(control_points);
  key_options.progress = o.progress;
  key_options.seed_points = o.fiducial_points;
  if (articulated) {
    // Every bone's 12 numbers fixed by its own points first; then keys enough for
    // kKeyEquationsPerUnknown equations per coordinate, never over kMaxKeyFraction of the points.
    // The selection runs to that count: every training frame is inside the articulated subspace
    // (its own transforms and residual coefficients fit it), so its error bound is met early and
    // says nothing of new motion, where each key's equations steady the least squares (crane,
    // 32 bones, trained on 60%: 272 keys at the bound, 0.95% of the diagonal median worst-point
    // error on the rest; 638 keys, 0.75%).
    key_options.error_bound = 0;
    for (int point : basis.skinning.coverage_points) key_options.seed_points.push_back(point);
    const int needed = static_cast<int>(std::ceil(kKeyEquationsPerUnknown * M / D));
    key_options.max_key_points = std::min(std::max(o.max_key_points, needed), max_key_count(control_points));
  }
  if (o.grid_cells > 0) {
    PointMatrix positions = o.positions;
    if (positions.rows() == 0) {
      if (D != 3) return invalid("grid_cells with channels ≠ 3 needs explicit positions");
      positions = Eigen::Map<const PointMatrix>(mean.head(control_points * D).cast<float>().eval().data(),
                                                control_points, 3);
    }
    if (positions.rows() != control_points) {
      return invalid("positions must have one row per control point (" + std::to_string(control_points) + ")");
    }
    for (int seed : grid_seeds(positions, o.grid_cells)) key_options.seed_points.push_back(seed);
  }
  return key_options;
}

// Regions for local fail-through (local_fail_through.h).
void assign_regions(const PcaBasis& pca, const ChosenBasis& basis, bool articulated, const TrainingOptions& o,
                    PmscModel& model) {
  const int D = o.channel_count;
  const TrainingBasis& subspace = basis.subspace;
    // Points that move together, by the training frames' principal components (for the
    // articulated kind too: its columns are not orthonormal, which the signatures assume).
    const Eigen::MatrixXd& motion_basis = articulated ? pca.basis : subspace.basis;
    const Eigen::VectorXd& motion_sigma = articulated ? pca.singular_values : subspace.sigma;
    Regions regions = cluster_regions(motion_basis, motion_sigma, D, model.key_points, o.region_count);
    model.region_count = regions.count;
    model.point_regions = std::move(regions.point_regions);
    model.key_regions = std::move(regions.key_regions);
    model.region_weights = soft_region_weights(motion_signatures(motion_basis, motion_sigma, D),
                                               model.point_regions, model.region_count);
}

// The basis of some of the training frames, made as the served one was made of all of them: the
// linear kind's principal components of those frames (at most M, and fewer than the frames), or
// the same skinning columns with the residual components of those frames alone (articulated).
// `residual` is scratch; writes out.mean and out.basis (reused storage, as fold_subspace's).
// Returns the residual components kept (articulated), or −1 when the frames are too few.
template <typename Scalar>
int subset_basis(const TrainingMatrix& T, const Eigen::MatrixXd& gram, const ChosenBasis& basis, bool articulated,
                 const std::vector<long>& frames, TrainingBasis& residual, SubspaceBasis<Scalar>& out) {
  if (articulated) {
    const ArticulatedSkinning& skinning = basis.skinning;
    const int residuals = static_cast<int>(std::min<long>(basis.residual_count, static_cast<long>(frames.size()) - 1));
    fold_subspace(TrainingMatrix(skinning.residuals), basis.residual_gram, frames, std::max(residuals, 1), residual);
    const long kept = residuals > 0 ? residual.basis.cols() : 0;
    out.mean = residual.mean;
    out.basis.resize(T.rows(), skinning.columns.cols() + kept);
    out.basis.leftCols(skinning.columns.cols()) = skinning.columns.template cast<Scalar>();
    out.basis.rightCols(kept) = residual.basis.leftCols(kept).template cast<Scalar>();
    return static_cast<int>(kept);
  }
  // M < F must hold for the subset too; fewer frames give a smaller subspace.
  const int count = static_cast<int>(std::min<long>(basis.M, static_cast<long>(frames.size()) - 1));
  if (count < 1) return -1;
  fold_subspace(T, gram, frames, count, out);
  return out.basis.cols() < 1 ? -1 : 0;
}

// The frames dealt into two halves by alternating blocks of `block` frames (the calibration's
// block length): each half holds out motion the other never saw, as a new shot is.
struct FrameHalves {
  std::vector<char> half;                  // F: 0 or 1
  std::array<std::vector<long>, 2> frames;  // each half's frames, ascending
  bool usable() const { return frames[0].size() >= 2 && frames[1].size() >= 2; }
};

FrameHalves alternating_halves(long F, long block) {
  FrameHalves out;
  out.half.resize(static_cast<size_t>(F));
  for (long f = 0; f < F; ++f) {
    out.half[static_cast<size_t>(f)] = static_cast<char>((f / std::max<long>(block, 1)) % 2);
    out.frames[static_cast<size_t>(out.half[static_cast<size_t>(f)])].push_back(f);
  }
  return out;
}

// The given frames of T less a subspace's mean (R × frames): what its key selection reconstructs.
Eigen::MatrixXd frames_less_mean(const TrainingMatrix& T, const std::vector<long>& frames,
                                 const Eigen::VectorXd& mean) {
  Eigen::MatrixXd columns(T.rows(), static_cast<long>(frames.size()));
  Eigen::VectorXd shift = -mean;
  if (T.offset().size() > 0) shift += T.offset();
  for (size_t j = 0; j < frames.size(); ++j) columns.col(static_cast<long>(j)) = T.col(frames[j]) + shift;
  return columns;
}

// Cross-fitted keys (issue #52): the served keys were chosen on every training frame, so a
// held-out frame's error is seen by the keys its own motion drew — a bump of skin in that frame
// put a key under it — and the calibration believes every such error visible. A new shot's is
// not. So keys are chosen again on each half of the frames alone (alternating_halves; as many as
// served, by the same rule), and a held-out frame is judged with the keys of the half it is not
// in: keys that never saw it, as the served keys never saw a new shot.
struct CrossFittedKeys {
  std::vector<char> half;                // F: 0 or 1; empty: not cross-fitted (too few frames)
  std::array<std::vector<int>, 2> keys;  // chosen on each half's frames alone
};

Result<CrossFittedKeys> cross_fitted_keys(const TrainingMatrix& T, const Eigen::MatrixXd& gram, const ChosenBasis& basis,
                                          bool articulated, KeyPointOptions options, long block, int key_count) {
  CrossFittedKeys out;
  FrameHalves halves = alternating_halves(T.cols(), block);
  if (!halves.usable()) return out;
  options.error_bound = 0;  // as many keys as served
  options.max_key_points = key_count;
  options.progress = {};
  TrainingBasis residual, half_basis;
  for (int h = 0; h < 2; ++h) {
    // The half's own basis and mean too: the served ones carry every frame's motion, and a
    // selection run to its key count chases even their faint trace of the other half.
    const std::vector<long>& mine = halves.frames[static_cast<size_t>(h)];
    if (subset_basis(T, gram, basis, articulated, mine, residual, half_basis) < 0) return CrossFittedKeys();
    auto selection = select_key_points(frames_less_mean(T, mine, half_basis.mean), half_basis.basis, options);
    if (!selection) return selection.error();
    out.keys[static_cast<size_t>(h)] = std::move(selection->key_points);
  }
  out.half = std::move(halves.half);
  return out;
}

// Issue #52 item 2: the key count by the accuracy the keys buy on motion they were not chosen
// on. The training frames' own error says little: each is reproduced by keys its motion drew,
// and the linear selection stops as soon as every one is within the bound (crane's 88 even
// frames: 48 keys at M = 80; train.h, max_basis_fraction). So on each half of the frames
// (alternating_halves) a basis is made and keys are chosen as the served ones are, and the other
// half's frames — motion that basis and keys never saw — are reconstructed from their key rows
// alone. Their worst point, averaged over the frames of both halves, is measured at key counts √2
// apart, from the served selection's stop up to kMaxKeyFraction of the points (no ladder when one
// step of √2 does not fit under it); each count continues the previous count's selection (the
// greedy selection with its keys as seeds), so the ladder costs one selection to its last rung.
// The count is the smallest rung within (1 + slack) of the best, or within the selection's bound
// (TrainingOptions::error_bound: keys the caller would stop at on its own training frames); the
// ladder stops at such a rung, or after two rungs in a row that each bought less than the slack.
// Worst point, not RMS: the verdict and the tolerance speak of the worst point (issue #52).
struct KeyBudget {
  std::vector<int> counts;      // the rungs measured
  std::vector<double> errors;   // mean held-out worst-point error at each, model units
  int count = 0;                // the chosen rung (0: no rule: too few frames or no room)
};

// Held-out frames per half the ladder measures, strided: the curve's mean needs no more, and a
// rung costs a reconstruction of each.
constexpr long kKeyBudgetFrames = 256;

Result<KeyBudget> held_out_key_budget(const TrainingMatrix& T, const Eigen::MatrixXd& gram, const ChosenBasis& basis,
                                      bool articulated, KeyPointOptions options, long block, int floor, int ceiling,
                                      double slack, double bound) {
  KeyBudget out;
  if (slack <= 0 || floor < 1) return out;
  const FrameHalves halves = alternating_halves(T.cols(), block);
  if (!halves.usable()) return out;
  // Whole rungs only: a last step short of √2 under the ceiling would cost a climb for a change
  // the slack rarely sees (crane's articulated kind: 638 → 800 keys, 0.557% → 0.547%).
  for (int next = floor; next <= ceiling; next = static_cast<int>(std::ceil(std::sqrt(2.0) * next))) {
    out.counts.push_back(next);
  }
  if (out.counts.size() < 2) return KeyBudget();
  options.error_bound = 0;
  options.progress = {};
  struct Half {
    TrainingBasis basis;
    Eigen::MatrixXd own, others;  // its frames and the other half's, less its basis's mean
    std::vector<int> keys;
  };
  // The halves are independent: each runs on a core of its own (the products inside it run
  // inline, parallel.h), and computes what it would alone.
  std::array<Half, 2> half;
  std::array<bool, 2> made{};
  parallel_for_chunks(2, 1, [&](int64_t first, int64_t last) {
    TrainingBasis residual;
    for (int64_t h = first; h < last; ++h) {
      Half& mine = half[static_cast<size_t>(h)];
      const std::vector<long>& own = halves.frames[static_cast<size_t>(h)];
      if (subset_basis(T, gram, basis, articulated, own, residual, mine.basis) < 0) continue;
      const std::vector<long>& other = halves.frames[static_cast<size_t>(1 - h)];
      const long stride = (static_cast<long>(other.size()) + kKeyBudgetFrames - 1) / kKeyBudgetFrames;
      std::vector<long> measured;
      for (size_t j = 0; j < other.size(); j += static_cast<size_t>(stride)) measured.push_back(other[j]);
      mine.own = frames_less_mean(T, own, mine.basis.mean);
      mine.others = frames_less_mean(T, measured, mine.basis.mean);
      mine.keys = options.seed_points;
      made[static_cast<size_t>(h)] = true;
    }
  });
  if (!made[0] || !made[1]) return KeyBudget();
  for (size_t rung = 0; rung < out.counts.size(); ++rung) {
    std::array<Status, 2> status{Status::Ok(), Status::Ok()};
    std::array<double, 2> sums{};
    parallel_for_chunks(2, 1, [&](int64_t first, int64_t last) {
      for (int64_t h = first; h < last; ++h) {
        Half& mine = half[static_cast<size_t>(h)];
        KeyPointOptions climb = options;
        climb.seed_points = mine.keys;
        climb.max_key_points = out.counts[rung];
        auto selection = select_key_points(mine.own, mine.basis.basis, climb);
        if (!selection) {
          status[static_cast<size_t>(h)] = selection.error();
          continue;
        }
        mine.keys = std::move(selection->key_points);
        sums[static_cast<size_t>(h)] =
            key_reconstruction_worst_errors(mine.others, mine.basis.basis, mine.keys, options.channel_count).sum();
      }
    });
    for (const Status& s : status) ANIMSPACE_RETURN_IF_ERROR(s);
    out.errors.push_back((sums[0] + sums[1]) / static_cast<double>(half[0].others.cols() + half[1].others.cols()));
    if (out.errors[rung] <= bound) break;
    if (rung >= 2 && out.errors[rung - 1] > (1 - slack) * out.errors[rung - 2] &&
        out.errors[rung] > (1 - slack) * out.errors[rung - 1]) {
      break;  // two rungs in a row bought less than the slack
    }
  }
  out.counts.resize(out.errors.size());
  const double best = *std::min_element(out.errors.begin(), out.errors.end());
  size_t chosen = 0;
  while (out.errors[chosen] > std::max((1 + slack) * best, bound)) ++chosen;
  out.count = out.counts[chosen];
  return out;
}

// The calibration's samples from every held-out set, joined in set order.
struct FoldSamples {
  std::vector<double> key, key_max, max;
  std::vector<char> half;  // the cross-fitting half of each sample's frame (CrossFittedKeys)
  std::vector<char> family;
  std::vector<Eigen::VectorXd> region_key, region_max;
  // Each sample's row of its point errors (HeldOutPointErrors), when they are kept: of the whole
  // errors when whole_row, else of the errors at the watched points.
  std::vector<long> error_row;
  std::vector<char> whole_row;
};

// The held-out samples' per-point errors as the folds keep them for the check points (issue #53
// item 2): whole rows (RelativePointErrors) for the samples the check points are chosen on, and
// for the other samples their errors at the chosen points only.
struct HeldOutPointErrors {
  RelativePointErrors whole;
  std::vector<int> watched;    // ascending: every point a check set of the model draws from
  Eigen::MatrixXf at_watched;  // rows × watched.size(), exact, in the samples' units

  // Sample i's error at `point` (of `watched` when the row is not whole).
  double error(const FoldSamples& folds, long i, int point, double max_error) const {
    const long row = folds.error_row[static_cast<size_t>(i)];
    if (folds.whole_row[static_cast<size_t>(i)]) return RelativePointErrors::error(whole.u(row, point), max_error);
    const auto at = std::lower_bound(watched.begin(), watched.end(), point);
    return static_cast<double>(at_watched(row, static_cast<long>(at - watched.begin())));
  }
};

// Which held-out sets keep their samples' whole point errors, and where each set's rows start.
// The check points are chosen on those samples. The selection needs a few hundred samples, while
// the whole errors grow with points × frames (186k points × 2,000 frames: 10,000 samples, 3.7 GB
// beside 4.5 GB of positions), so they are kept whole while they fit in max(kWholeErrorFloorBytes,
// kWholeErrorShare of the training positions' bytes) or the caller's budget; past that each fold
// family keeps the share of its sets that fits (at least one), strided along the family so that
// its block lengths and folds are all drawn on. The other sets run after the choice.
constexpr double kWholeErrorFloorBytes = 256.0 * (1 << 20);
constexpr double kWholeErrorShare = 1.0 / 8;
struct PointErrorPlan {
  std::vector<char> whole;      // per set
  std::vector<long> first_row;  // per set: its first held-out frame's row in the store it writes
  long whole_rows = 0, watched_rows = 0;
};

PointErrorPlan point_error_plan(const HeldOutSets& held, long points, double positions_bytes, long long budget_option) {
  const std::vector<HeldOutSet>& sets = held.sets;
  PointErrorPlan plan;
  plan.whole.assign(sets.size(), 1);
  long samples = 0;
  for (const HeldOutSet& set : sets) samples += static_cast<long>(set.held_out.size());
  const double budget = budget_option > 0 ? static_cast<double>(budget_option)
                                          : std::max(kWholeErrorFloorBytes, kWholeErrorShare * positions_bytes);
  const double whole_bytes = static_cast<double>(samples) * static_cast<double>(points) * sizeof(std::uint16_t);
  if (whole_bytes > budget) {
    const double share = budget / whole_bytes;
    for (char family : {kInterleavedFold, kSparseFold, kBlockFold}) {
      std::vector<size_t> members;
      for (size_t s = 0; s < sets.size(); ++s) {
        if (sets[s].family == family) members.push_back(s);
      }
      if (members.empty()) continue;
      const auto count = static_cast<double>(members.size());
      const auto keep = static_cast<size_t>(std::clamp(std::floor(share * count), 1.0, count));
      for (size_t s : members) plan.whole[s] = 0;
      for (size_t j = 0; j < keep; ++j) {
        plan.whole[members[static_cast<size_t>((static_cast<double>(j) + 0.5) * count / static_cast<double>(keep))]] = 1;
      }
    }
  }
  plan.first_row.resize(sets.size());
  for (size_t s = 0; s < sets.size(); ++s) {
    long& rows = plan.whole[s] ? plan.whole_rows : plan.watched_rows;
    plan.first_row[s] = rows;
    rows += static_cast<long>(sets[s].held_out.size());
  }
  return plan;
}

  // ε from held-out training frames only (calibration.h): retrain the subspace without each
  // fold (same keys, same M), evaluate its frames through the runtime, and keep (e_key, true max
  // point error, each point's error) of every held-out frame, overall and per region. Three fold
  // families: every `folds`-th frame (poses between training poses); blocks of consecutive frames
  // at three lengths, dealt to the folds in turn (motion the rest of the training never saw); and
  // sparse folds, trained on every other frame an interleaved fold keeps (a model that saw less).
  // Runs the sets `run` into per_set[set]; each held-out sample's point errors go to `errors` (when
  // not null) where `plan` says: whole, or at errors->watched. Progress counts on from `already`.
void calibration_samples(const FrameMatrix& control_frames, const FrameMatrix* output_frames, const TrainingMatrix& T,
                         const Eigen::MatrixXd& gram, const HeldOutSets& held_sets, const ChosenBasis& basis,
                         const CrossFittedKeys& crossfit, bool articulated, PmscModel& model, const TrainingOptions& o,
                         const std::vector<size_t>& run, const PointErrorPlan& plan, HeldOutPointErrors* errors,
                         std::vector<FoldSamples>& per_set, size_t already) {
  const int D = o.channel_count;
  const bool cross = output_frames != nullptr;
  const long control_rows = control_frames.cols();
  const std::vector<HeldOutSet>& sets = held_sets.sets;
  const long R_count = model.region_count;
  const long N_out = model.point_count;
  // A held-out frame's row of the point errors is fixed by the plan before any fold runs, so that
  // the sets write theirs in parallel (a frame a fold could not judge leaves its row unread).
  // Every set is independent of the others (issue #38 item 3): the sets run on all cores, each
  // worker taking the next set not yet taken (their costs differ: a sparse fold trains on half
  // the frames), each writing its own samples; they are joined in set order afterwards, so the
  // model is the same whatever the thread count. The products inside a set are not split again
  // (parallel.h), so a set computes exactly what a one-thread training computes.
  std::atomic<size_t> next_set{0};
  std::mutex progress_mutex;
  size_t sets_done = already;
  // What a worker keeps from one set to the next (fold_subspace): the fold's subspace, its model
  // (the trained model's members without the basis, which assemble replaces) and the batch's
  // reconstructed points.
  Eigen::MatrixXf served_basis = std::move(model.basis);  // moved-from Eigen matrices are empty
  Eigen::VectorXf served_mean = std::move(model.mean);
  const PmscModel shell = model;
  model.basis = std::move(served_basis);
  model.mean = std::move(served_mean);
  struct Workspace {
    FoldBasis fold;
    TrainingBasis residual;  // articulated: the fold's residual components
    PmscModel model;
    Eigen::MatrixXf points;
    std::vector<PoseEstimate> estimates;
  };
  const auto calibrate_set = [&](size_t set, Workspace& work) {
    const HeldOutSet& held = sets[set];
    FoldSamples& out = per_set[set];
    const int kept_residuals = subset_basis(T, gram, basis, articulated, held.train, work.residual, work.fold);
    if (kept_residuals < 0) return;
    if (articulated) work.model.residual_components = kept_residuals;
    PmscModel& fold_model = work.model;
    // The fold's float basis is already the model's rows unless a cross model's control rows or a
    // relative model's extra column come between: then it is lent to the model, not copied (one
    // R × M buffer per worker, handed back below for the next fold to reuse).
    const bool lent = !cross && !fold_model.relative_tolerance;
    if (lent) {
      fold_model.mean = work.fold.mean.cast<float>();
      fold_model.basis.swap(work.fold.basis);
    }
    // Each held-out frame is judged with keys that never saw it (CrossFittedKeys): those of the
    // other half; without cross-fitting, the served keys.
    const int halves = crossfit.half.empty() ? 1 : 2;
    for (int h = 0; h < halves; ++h) {
      std::vector<long> judged;  // positions in held.held_out
      for (size_t p = 0; p < held.held_out.size(); ++p) {
        const long f = held.held_out[p];
        if (halves == 1 || crossfit.half[static_cast<size_t>(f)] == h) judged.push_back(static_cast<long>(p));
      }
      if (judged.empty()) continue;
      const std::vector<int>& keys = halves == 1 ? model.key_points : crossfit.keys[static_cast<size_t>(1 - h)];
      const Status placed = lent ? place_keys(work.fold.mean, fold_model.basis, Eigen::VectorXd(), keys, fold_model)
                                 : assemble(work.fold, control_rows, cross, keys, fold_model);
      if (!placed.ok()) continue;
      if (R_count > 0) {
        fold_model.key_regions.resize(keys.size());
        for (size_t k = 0; k < keys.size(); ++k) {
          fold_model.key_regions[k] = model.point_regions[static_cast<size_t>(keys[k])];
        }
      }
      // The fold's runtime, as a server would build it (non-owning: fold_model outlives it).
      const auto runtime =
          make_subspace(std::shared_ptr<const PmscModel>(std::shared_ptr<const PmscModel>(), &fold_model));
      if (!runtime) continue;
      const pmsc::Subspace& fold_runtime = **runtime;
      // The held-out frames go through the runtime as a server's batch does (estimate, then one
      // reconstruct per kCalibrationBatch poses): the basis is read once per batch, not per frame.
      const long count = static_cast<long>(judged.size());
      for (long first = 0; first < count; first += kCalibrationBatch) {
        const long batch = std::min(kCalibrationBatch, count - first);
        work.estimates.resize(static_cast<size_t>(batch));
        work.points.resize(fold_model.mean.size(), batch);
        std::vector<const PoseEstimate*> estimates(static_cast<size_t>(batch));
        std::vector<float*> destinations(static_cast<size_t>(batch));
        for (long b = 0; b < batch; ++b) {
          // Held-out frames enter in the world frame, as at run time.
          const long f = held.held_out[static_cast<size_t>(judged[static_cast<size_t>(first + b)])];
          const Eigen::VectorXf control = control_frames.row(f).transpose();
          fold_runtime.estimate(gather_key_values(fold_model, control), Eigen::VectorXf(),
                                work.estimates[static_cast<size_t>(b)]);
          estimates[static_cast<size_t>(b)] = &work.estimates[static_cast<size_t>(b)];
          destinations[static_cast<size_t>(b)] = work.points.col(b).data();
        }
        fold_runtime.reconstruct(estimates, destinations);
        for (long b = 0; b < batch; ++b) {
          const long position = judged[static_cast<size_t>(first + b)];
          const long f = held.held_out[static_cast<size_t>(position)];
          const PoseEstimate& estimate = work.estimates[static_cast<size_t>(b)];
          const Eigen::VectorXf truth =
              cross ? Eigen::VectorXf(output_frames->row(f).transpose()) : Eigen::VectorXf(control_frames.row(f).transpose());
          const Eigen::VectorXf residual = truth - work.points.col(b);
          // In the units of the estimate's errors: fractions of the pose's scale S when relative.
          const Eigen::VectorXf point_errors =
              Eigen::Map<const Eigen::MatrixXf>(residual.data(), D, N_out).colwise().norm().transpose() /
              static_cast<float>(estimate.scale);
          out.key.push_back(estimate.key_point_error);
          out.key_max.push_back(estimate.key_point_max_error);
          const float largest = point_errors.maxCoeff();
          out.max.push_back(static_cast<double>(largest));
          if (errors != nullptr) {
            const long row = plan.first_row[set] + position;
            out.error_row.push_back(row);
            out.whole_row.push_back(plan.whole[set]);
            if (plan.whole[set]) {
              for (long i = 0; i < N_out && largest > 0; ++i) {
                errors->whole.u(row, i) = RelativePointErrors::quantise(point_errors(i), largest);
              }
            } else {
              for (size_t w = 0; w < errors->watched.size(); ++w) {
                errors->at_watched(row, static_cast<long>(w)) = point_errors(errors->watched[w]);
              }
            }
          }
          if (R_count > 0) {
            Eigen::VectorXd region_max = Eigen::VectorXd::Zero(R_count);
            for (long i = 0; i < N_out; ++i) {
              double& m = region_max(model.point_regions[static_cast<size_t>(i)]);
              m = std::max(m, static_cast<double>(point_errors(i)));
            }
            out.region_key.push_back(Eigen::Map<const Eigen::VectorXd>(estimate.region_errors.data(), R_count));
            out.region_max.push_back(region_max);
          }
          out.half.push_back(static_cast<char>(h));
        }
      }
    }
    if (lent) fold_model.basis.swap(work.fold.basis);
  };
  if (already == 0) report_progress(o.progress, "calibration", 0, static_cast<int>(sets.size()));
  parallel_for_chunks(static_cast<int64_t>(run.size()), 1, [&](int64_t, int64_t) {
    Workspace work{FoldBasis(), TrainingBasis(), shell, Eigen::MatrixXf(), {}};
    for (size_t next = next_set++; next < run.size(); next = next_set++) {
      calibrate_set(run[next], work);
      const std::lock_guard<std::mutex> lock(progress_mutex);
      if (++sets_done < sets.size()) {
        report_progress(o.progress, "calibration", static_cast<int>(sets_done), static_cast<int>(sets.size()));
      }
    }
  });
}

// Every set's samples, joined in set order (whatever order the sets ran in).
FoldSamples join_samples(std::vector<FoldSamples>& per_set, const std::vector<HeldOutSet>& sets) {
  FoldSamples joined;
  for (size_t set = 0; set < sets.size(); ++set) {
    FoldSamples& out = per_set[set];
    joined.key.insert(joined.key.end(), out.key.begin(), out.key.end());
    joined.key_max.insert(joined.key_max.end(), out.key_max.begin(), out.key_max.end());
    joined.max.insert(joined.max.end(), out.max.begin(), out.max.end());
    joined.family.insert(joined.family.end(), out.key.size(), sets[set].family);
    joined.half.insert(joined.half.end(), out.half.begin(), out.half.end());
    for (auto& v : out.region_key) joined.region_key.push_back(std::move(v));
    for (auto& v : out.region_max) joined.region_max.push_back(std::move(v));
    joined.error_row.insert(joined.error_row.end(), out.error_row.begin(), out.error_row.end());
    joined.whole_row.insert(joined.whole_row.end(), out.whole_row.begin(), out.whole_row.end());
    out = FoldSamples();
  }
  return joined;
}

// ⌈fraction · K⌉ check points (none for a cross model).
int check_point_count(const TrainingOptions& o, bool cross, long key_points) {
  return cross ? 0 : static_cast<int>(std::ceil(o.check_point_fraction * static_cast<double>(key_points) - 1e-9));
}

// The check points (check_points.h): the served ones, chosen on every sample whose whole point
// errors were kept, and, when the keys were cross-fitted (CrossFittedKeys), those of each half:
// chosen on the other half's samples, which were judged with its keys, so that a sample's e_check
// comes from check points chosen without it.
struct CheckPointChoice {
  std::vector<int> served;
  std::array<std::vector<int>, 2> of_half;  // the check points that measure each half's samples
  long samples = 0;                         // the samples chosen on
};

CheckPointChoice choose_check_points(const std::vector<FoldSamples>& per_set, const PointErrorPlan& plan,
                                     const RelativePointErrors& errors, const CrossFittedKeys& crossfit,
                                     const TrainingOptions& o, const PmscModel& model, int count) {
  CheckPointChoice choice;
  const long rows = errors.u.rows();
  // By row of the whole errors: each sample's max, its half, and whether it was judged at all.
  Eigen::VectorXd row_max = Eigen::VectorXd::Zero(rows);
  std::vector<char> judged(static_cast<size_t>(rows), 0), half(static_cast<size_t>(rows), 0);
  for (size_t set = 0; set < per_set.size(); ++set) {
    if (!plan.whole[set]) continue;
    const FoldSamples& samples = per_set[set];
    for (size_t i = 0; i < samples.error_row.size(); ++i) {
      const auto row = static_cast<size_t>(samples.error_row[i]);
      row_max(static_cast<long>(row)) = samples.max[i];
      judged[row] = 1;
      half[row] = samples.half[i];
      ++choice.samples;
    }
  }
  const double noise_floor = kCalibrationNoiseFraction * o.error_tolerance;
  choice.served = select_check_points(errors, judged, row_max, model.key_points, model.point_regions,
                                      model.region_count, count, noise_floor);
  choice.of_half = {choice.served, choice.served};
  if (crossfit.half.empty() || choice.served.empty()) return choice;
  for (int h = 0; h < 2; ++h) {
    std::vector<char> others(static_cast<size_t>(rows));
    for (size_t row = 0; row < others.size(); ++row) others[row] = judged[row] && half[row] != h;
    std::vector<int> chosen =
        select_check_points(errors, others, row_max, crossfit.keys[static_cast<size_t>(1 - h)], model.point_regions,
                            model.region_count, static_cast<int>(choice.served.size()), noise_floor);
    // (A half whose other half kept no whole errors is measured by the served check points.)
    if (!chosen.empty()) choice.of_half[static_cast<size_t>(h)] = std::move(chosen);
  }
  return choice;
}

// Every point a check set of the choice draws from, ascending.
std::vector<int> watched_points(const CheckPointChoice& choice) {
  std::vector<int> points = choice.served;
  for (const auto& checks : choice.of_half) points.insert(points.end(), checks.begin(), checks.end());
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  return points;
}

// The samples into the model's calibration, with the chosen check points and each sample's
// e_check (and its regions') from the check points of its half.
void store_samples(FoldSamples folds, const HeldOutPointErrors& errors, const CheckPointChoice& choice,
                   const CrossFittedKeys& crossfit, PmscModel& model) {
  const long R_count = model.region_count;
  CalibrationSamples& samples = model.calibration.samples;
  const long n = static_cast<long>(folds.key.size());
  samples.key_point_errors = Eigen::Map<const Eigen::VectorXd>(folds.key.data(), n);
  samples.key_point_max_errors = Eigen::Map<const Eigen::VectorXd>(folds.key_max.data(), n);
  samples.max_errors = Eigen::Map<const Eigen::VectorXd>(folds.max.data(), n);
  samples.region_key_point_errors.resize(R_count > 0 ? n : 0, R_count);
  samples.region_max_errors.resize(R_count > 0 ? n : 0, R_count);
  for (long i = 0; i < n && R_count > 0; ++i) {
    samples.region_key_point_errors.row(i) = folds.region_key[static_cast<size_t>(i)].transpose();
    samples.region_max_errors.row(i) = folds.region_max[static_cast<size_t>(i)].transpose();
  }
  samples.fold_family = std::move(folds.family);

  model.check_points = choice.served;
  if (model.check_points.empty() || n == 0) return;
  for (int point : model.check_points) {
    if (R_count > 0) model.check_regions.push_back(model.point_regions[static_cast<size_t>(point)]);
  }
  const bool halves = !crossfit.half.empty();
  samples.check_point_errors = Eigen::VectorXd::Zero(n);
  samples.region_check_point_errors = Eigen::MatrixXd::Zero(R_count > 0 ? n : 0, R_count);
  for (long i = 0; i < n; ++i) {
    const int h = halves ? folds.half[static_cast<size_t>(i)] : 0;
    for (int point : choice.of_half[static_cast<size_t>(h)]) {
      const double error = errors.error(folds, i, point, samples.max_errors(i));
      samples.check_point_errors(i) = std::max(samples.check_point_errors(i), error);
      if (R_count > 0) {
        double& region = samples.region_check_point_errors(i, model.point_regions[static_cast<size_t>(point)]);
        region = std::max(region, error);
      }
    }
  }
}

Result<PmscModel> train_joint(const FrameMatrix& control_frames, const FrameMatrix* output_frames,
                              const TrainingOptions& o, TrainingReport* report) {
  const auto start = std::chrono::steady_clock::now();
  ANIMSPACE_RETURN_IF_ERROR(check_training_input(control_frames, output_frames, o));
  const int D = o.channel_count;
  const long F = control_frames.rows();
  const bool cross = output_frames != nullptr;
  const long control_points = control_frames.cols() / D;
  const bool articulated = o.subspace_kind == SubspaceKind::kArticulated;

  // T: R × F, control rows first, read in double (PCA and least squares at training time deserve
  // it) from the frames themselves (training_matrix.h): the caller's F × R row-major float32
  // frames are T's bytes. Only what must change them takes a double copy: the control and output
  // rows of a cross model stacked, the frames with their rigid motion removed.
  const long control_rows = control_frames.cols();
  const long rows = control_rows + (cross ? output_frames->cols() : 0);
  Eigen::MatrixXd stacked;
  if (cross || o.remove_rigid_motion) {
    stacked.resize(rows, F);
    stacked.topRows(control_rows) = control_frames.transpose().cast<double>();
    if (cross) stacked.bottomRows(rows - control_rows) = output_frames->transpose().cast<double>();
  }

  PmscModel model;
  model.channel_count = D;
  model.cross = cross;
  model.control_point_count = static_cast<int>(control_points);
  model.point_count = static_cast<int>((rows - (cross ? control_rows : 0)) / D);
  model.aligned = o.remove_rigid_motion;
  model.relative_tolerance = o.relative_tolerance;
  // Issue #52: the worst key's residual joins e_check in the verdict (ErrorEstimator). Measured
  // against e_key in the same bench run on both kinds (docs/BENCHMARKS.md): as many bad frames
  // flagged and more good ones hit on new shots of the articulated kind, the same on the linear.
  model.estimator = ErrorEstimator::kWorstPoint;
  if (o.remove_rigid_motion) {
    const auto transforms = rigid_motion_per_frame(stacked, control_points);
    for (long f = 0; f < F; ++f) apply_inverse(transforms[static_cast<size_t>(f)], stacked.col(f));
  }
  const TrainingMatrix T = stacked.size() > 0 ? TrainingMatrix(stacked) : TrainingMatrix(control_frames.data(), rows, F);
  const HeldOutSets held = held_out_sets(F, o);

  // The basis: principal components of the training matrix (2007 §2.1), or the skinning and
  // its residual components.
  const auto pca_start = std::chrono::steady_clock::now();
  const Eigen::VectorXd mean = T.value_mean();
  const TrainingMatrix centred = T.with_offset(mean);
  const int max_basis = static_cast<int>(std::min<long>(o.max_basis, F - 1));
  const int chosen_cap = std::max(1, std::min(max_basis, static_cast<int>(o.max_basis_fraction * static_cast<double>(F))));
  PcaBasis pca = thin_pca(centred, max_basis);
  if (pca.basis.cols() == 0) return invalid("the training frames are all identical: there is no motion to model");
  // The folds' Gram matrix (fold_subspace): of the centred frames, which it cannot tell from T's
  // but for rounding, and rounds less.
  const Eigen::MatrixXd gram = centred.gram();
  ChosenBasis basis;
  if (articulated) {
    auto fitted = articulated_basis(control_frames, T, held, chosen_cap, o);
    if (!fitted) return fitted.error();
    basis = std::move(*fitted);
  } else {
    basis = linear_basis(centred, std::move(pca), gram, held, chosen_cap, o);
  }
  const int M = basis.M;
  const double pca_seconds = seconds_since(pca_start);

  // Key points (2007 §2.2).
  const auto key_start = std::chrono::steady_clock::now();
  auto key_options = key_point_options(o, basis, mean, control_points, articulated);
  if (!key_options) return key_options.error();
  // What the key selection reconstructs: the frames less the subspace's mean (the linear kind's is
  // the frames' mean).
  const TrainingMatrix selected_from = T.with_offset(basis.subspace.mean);
  auto selection = select_key_points(selected_from, basis.subspace.basis, *key_options);
  if (!selection) return selection.error();
  // Then as many more as the held-out rule finds worth their cost (held_out_key_budget).
  auto budget = held_out_key_budget(centred, gram, basis, articulated, *key_options, held.block,
                                    static_cast<int>(selection->key_points.size()), max_key_count(control_points),
                                    o.held_out_key_slack, o.error_bound);
  if (!budget) return budget.error();
  if (budget->count > static_cast<int>(selection->key_points.size())) {
    KeyPointOptions more = *key_options;
    more.error_bound = 0;
    more.seed_points = selection->key_points;
    more.max_key_points = budget->count;
    auto continued = select_key_points(selected_from, basis.subspace.basis, more);
    if (!continued) return continued.error();
    selection->key_points = std::move(continued->key_points);
    // (Its first residual is the served selection's last, measured again with the same keys.)
    const std::vector<double>& after = continued->max_residual;
    selection->max_residual.insert(selection->max_residual.end(), after.begin() + (after.empty() ? 0 : 1), after.end());
  }
  // The keys of each half of the frames, when the calibration is cross-fitted (CrossFittedKeys).
  Result<CrossFittedKeys> crossfit = CrossFittedKeys();
  if (o.cross_fitted_calibration == 1) {
    crossfit = cross_fitted_keys(centred, gram, basis, articulated, *key_options, held.block,
                                 static_cast<int>(selection->key_points.size()));
    if (!crossfit) return crossfit.error();
  }
  const double key_selection_seconds = seconds_since(key_start);
  model.subspace_kind = o.subspace_kind;
  model.bone_count = articulated ? basis.skinning.bone_count : 0;
  model.residual_components = articulated ? basis.residual_count : 0;
  ANIMSPACE_RETURN_IF_ERROR(assemble(basis.subspace, control_rows, cross, selection->key_points, model));

  // Regions for local fail-through (the keys index the same points only without cross).
  if (!cross && o.region_count > 0) assign_regions(pca, basis, articulated, o, model);
  // Not read again: the articulated kind's full PCA and the served basis in double (the model has
  // it in float; the folds make their own) go before the calibration folds allocate theirs
  // (issue #53: at 186k points and M = 133 the basis alone is 0.6 GB).
  pca = PcaBasis{};
  basis.subspace.basis = Eigen::MatrixXd();

  // Calibration (calibration.h) and check points: the sets that keep their samples' whole point
  // errors first, then the check points chosen on them, then the other sets, which keep their
  // samples' errors at the chosen points (point_error_plan).
  const auto calibration_start = std::chrono::steady_clock::now();
  const int check_count = check_point_count(o, cross, model.key_point_count());
  const double positions_bytes =
      static_cast<double>(control_frames.size() + (cross ? output_frames->size() : 0)) * sizeof(float);
  const PointErrorPlan plan = point_error_plan(held, model.point_count, positions_bytes, o.point_error_budget_bytes);
  HeldOutPointErrors errors;
  std::vector<FoldSamples> per_set(held.sets.size());
  std::vector<size_t> whole_sets, watched_sets;
  for (size_t set = 0; set < held.sets.size(); ++set) (plan.whole[set] ? whole_sets : watched_sets).push_back(set);
  const auto run_sets = [&](const std::vector<size_t>& run, size_t already) {
    calibration_samples(control_frames, output_frames, centred, gram, held, basis, *crossfit, articulated, model, o,
                        run, plan, check_count > 0 ? &errors : nullptr, per_set, already);
  };
  if (check_count > 0) errors.whole.u.setZero(plan.whole_rows, model.point_count);
  run_sets(whole_sets, 0);
  CheckPointChoice choice;
  if (check_count > 0) {
    choice = choose_check_points(per_set, plan, errors.whole, *crossfit, o, model, check_count);
    errors.watched = watched_points(choice);
    errors.at_watched.setZero(plan.watched_rows, static_cast<long>(errors.watched.size()));
  }
  run_sets(watched_sets, whole_sets.size());
  report_progress(o.progress, "calibration", static_cast<int>(held.sets.size()), static_cast<int>(held.sets.size()));
  FoldSamples folds = join_samples(per_set, held.sets);
  const long n = static_cast<long>(folds.key.size());
  store_samples(std::move(folds), errors, choice, *crossfit, model);
  errors = HeldOutPointErrors();
  model.calibration.false_hit_rate = o.false_hit_rate;
  model.calibration.block_frames = static_cast<int>(held.block);
  ANIMSPACE_RETURN_IF_ERROR(apply_calibration(model, o.error_tolerance, o.blend_zone_ratio));
  ANIMSPACE_RETURN_IF_ERROR(prepare_projection(model));  // the check rows

  if (report) {
    const std::vector<double>& held_out_rms = basis.held_out_rms;
    const double projection_error = basis.projection_error;
    const ArticulatedSkinning& skinning = basis.skinning;
    const double skinning_seconds = basis.skinning_seconds;
    report->frames = static_cast<int>(F);
    report->basis_size = M;
    report->held_out_relative_rms = held_out_rms;
    report->pca_seconds = pca_seconds;
    report->key_selection_seconds = key_selection_seconds;
    report->key_points = model.key_point_count();
    report->key_budget_counts = budget->counts;
    report->key_budget_errors = budget->errors;
    report->max_residual_per_iteration = selection->max_residual;
    report->max_training_error = selection->max_residual.empty() ? 0 : selection->max_residual.back();
    if (model.relative_tolerance) {
      // The keys were chosen for the affine subspace; the linear one served has the mean's
      // direction too, so its training error is measured on the model itself (model units).
      report->max_training_error = 0;
      PoseEstimate estimate;
      for (long f = 0; f < F; ++f) {
        const Eigen::VectorXf control = control_frames.row(f).transpose();
        const Eigen::VectorXf truth = cross ? Eigen::VectorXf(output_frames->row(f).transpose()) : control;
        evaluate(model, gather_key_values(model, control), estimate);
        const Eigen::VectorXf residual = truth - estimate.points;
        report->max_training_error =
            std::max(report->max_training_error,
                     static_cast<double>(Eigen::Map<const Eigen::MatrixXf>(residual.data(), D, model.point_count)
                                             .colwise()
                                             .norm()
                                             .maxCoeff()));
      }
    }
    // (The articulated selection runs past the bound to its key count: converged is whether it
    // ended within the bound.)
    report->converged = articulated ? report->max_training_error <= o.error_bound : selection->converged;
    report->projection_error = projection_error;
    report->basis_capped = o.basis_size <= 0 && M == chosen_cap && projection_error > 0.5 * o.error_bound;
    report->condition_number = model.condition_number;
    report->regularization = model.regularization;
    report->error_ratio = model.calibration.error_ratio;
    report->calibration_frames = static_cast<int>(n);
    report->check_points = model.check_point_count();
    report->check_point_samples = static_cast<int>(choice.samples);
    report->bones = model.bone_count;
    report->residual_components = model.residual_components;
    report->skinning_rms = skinning.rms;
    report->skinning_seconds = skinning_seconds;
    report->calibration_bad_samples = model.calibration.bad_samples;
    const auto now = std::chrono::steady_clock::now();
    report->seconds = std::chrono::duration<double>(now - start).count();
    report->calibration_seconds = std::chrono::duration<double>(now - calibration_start).count();
  }
  return model;
}

}  // namespace

Result<PmscModel> train(const FrameMatrix& frames, const TrainingOptions& options, TrainingReport* report) {
  return train_joint(frames, nullptr, options, report);
}

Result<PmscModel> train_cross(const FrameMatrix& control_frames, const FrameMatrix& output_frames,
                              const TrainingOptions& options, TrainingReport* report) {
  return train_joint(control_frames, &output_frames, options, report);
}

double held_out_block_fraction(const PmscModel& model, double tolerance, long* samples) {
  const CalibrationSamples& s = model.calibration.samples;
  long count = 0, within = 0;
  for (long i = 0; i < s.size(); ++i) {
    if (s.fold_family[static_cast<size_t>(i)] != kBlockFold) continue;
    ++count;
    within += s.max_errors(i) <= tolerance ? 1 : 0;
  }
  if (samples) *samples = count;
  return count > 0 ? static_cast<double>(within) / static_cast<double>(count) : 0.0;
}

Result<PmscModel> train_best_kind(const FrameMatrix& frames, const TrainingOptions& options, TrainingReport* report,
                                  SubspaceChoice* choice) {
  TrainingOptions linear_options = options;
  linear_options.subspace_kind = SubspaceKind::kLinear;
  TrainingReport linear_report;
  auto linear = train(frames, linear_options, &linear_report);
  if (!linear) return linear.error();
  TrainingOptions articulated_options = options;
  articulated_options.subspace_kind = SubspaceKind::kArticulated;
  articulated_options.remove_rigid_motion = false;  // the bones carry the rigid motion
  TrainingReport articulated_report;
  auto articulated = train(frames, articulated_options, &articulated_report);

  SubspaceChoice made;
  made.linear_block_within_tolerance = held_out_block_fraction(*linear, options.error_tolerance, &made.block_samples);
  const auto percent = [](double fraction) { return std::to_string(static_cast<int>(std::lround(100 * fraction))) + "%"; };
  if (!articulated) {
    made.reason = "linear: the articulated kind could not be trained (" + articulated.error().message + ")";
  } else {
    made.articulated_block_within_tolerance = held_out_block_fraction(*articulated, options.error_tolerance);
    const bool better = made.articulated_block_within_tolerance > made.linear_block_within_tolerance;
    made.kind = better ? SubspaceKind::kArticulated : SubspaceKind::kLinear;
    made.reason = std::string(better ? "articulated" : "linear") + ": on held-out blocks of the training frames (" +
                  std::to_string(made.block_samples) + " samples, motion each fold never saw) the articulated kind is "
                  "within the tolerance on " + percent(made.articulated_block_within_tolerance) +
                  ", the linear kind on " + percent(made.linear_block_within_tolerance) +
                  (better ? "" : " (a tie keeps the linear kind, the cheaper to train)");
  }
  if (choice) *choice = made;
  const bool keep_articulated = made.kind == SubspaceKind::kArticulated;
  if (report) *report = keep_articulated ? articulated_report : linear_report;
  if (keep_articulated) return std::move(*articulated);
  return std::move(*linear);
}

double bounding_box_diagonal(const Eigen::Ref<const Eigen::VectorXf>& frame) {
  const Eigen::Map<const Eigen::Matrix3Xf> points(frame.data(), 3, frame.size() / 3);
  return static_cast<double>((points.rowwise().maxCoeff() - points.rowwise().minCoeff()).norm());
}

}  // namespace animspace::pmsc
