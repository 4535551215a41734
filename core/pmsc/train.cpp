#include "core/pmsc/train.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <string>

#include "core/pmsc/key_points.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/regions.h"
#include "core/geometry/rigid_fit.h"

namespace animspace::pmsc {
namespace {

// Held-out frames whose e_key is below this fraction of the tolerance (reproduced to rounding)
// are not used to calibrate ε.
constexpr double kNoiseFraction = 1e-4;

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

struct Subspace {
  Eigen::VectorXd mean;    // R
  Eigen::MatrixXd basis;   // R × M
  Eigen::VectorXd sigma;   // M
};

Subspace fit_subspace(const Eigen::MatrixXd& T_world_or_aligned, int M) {
  Subspace s;
  s.mean = T_world_or_aligned.rowwise().mean();
  const Eigen::MatrixXd centred = T_world_or_aligned.colwise() - s.mean;
  PcaBasis pca = thin_pca(centred, M);
  s.basis = std::move(pca.basis);
  s.sigma = pca.singular_values.head(s.basis.cols());
  return s;
}

// Copies the output rows and the key rows of a subspace into a runtime model and prepares it.
Status assemble(const Subspace& s, long control_rows, bool cross, const std::vector<int>& keys, PmscModel& m) {
  const long D = m.channel_count;
  const long output_first = cross ? control_rows : 0;
  const long output_rows = s.mean.size() - output_first;
  m.mean = s.mean.segment(output_first, output_rows).cast<float>();
  m.basis = s.basis.middleRows(output_first, output_rows).cast<float>();
  m.key_points = keys;
  Eigen::VectorXd key_mean(static_cast<long>(keys.size()) * D);
  for (size_t k = 0; k < keys.size(); ++k) {
    key_mean.segment(static_cast<long>(k) * D, D) = s.mean.segment(static_cast<long>(keys[k]) * D, D);
  }
  m.key_mean = key_mean;
  m.key_basis = gather_key_rows(s.basis, keys, static_cast<int>(D));
  return prepare_projection(m);
}

Result<PmscModel> train_joint(const FrameMatrix& control_frames, const FrameMatrix* output_frames,
                              const TrainingOptions& o, TrainingReport* report) {
  const auto start = std::chrono::steady_clock::now();
  const int D = o.channel_count;
  const long F = control_frames.rows();
  // Validation: every rule names the option or the data.
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
  if (o.blend_zone_ratio < 1) return invalid("blend_zone_ratio must be ≥ 1");
  if (!(o.max_basis_fraction > 0 && o.max_basis_fraction <= 1)) return invalid("max_basis_fraction must be in (0, 1]");
  const bool cross = output_frames != nullptr;
  const long control_points = control_frames.cols() / D;

  // T: R × F, control rows first, in double: PCA and least squares at training time deserve it.
  const long control_rows = control_frames.cols();
  const long rows = control_rows + (cross ? output_frames->cols() : 0);
  Eigen::MatrixXd T(rows, F);
  T.topRows(control_rows) = control_frames.transpose().cast<double>();
  if (cross) T.bottomRows(rows - control_rows) = output_frames->transpose().cast<double>();

  PmscModel model;
  model.channel_count = D;
  model.cross = cross;
  model.control_point_count = static_cast<int>(control_points);
  model.point_count = static_cast<int>((rows - (cross ? control_rows : 0)) / D);
  model.aligned = o.remove_rigid_motion;
  if (o.remove_rigid_motion) {
    const auto transforms = rigid_motion_per_frame(T, control_points);
    for (long f = 0; f < F; ++f) apply_inverse(transforms[static_cast<size_t>(f)], T.col(f));
  }

  // Runtime basis from the initial training matrix (2007 §2.1).
  const Eigen::VectorXd mean = T.rowwise().mean();
  const Eigen::MatrixXd centred = T.colwise() - mean;
  const int max_basis = static_cast<int>(std::min<long>(o.max_basis, F - 1));
  const int chosen_cap = std::max(1, std::min(max_basis, static_cast<int>(o.max_basis_fraction * static_cast<double>(F))));
  const PcaBasis pca = thin_pca(centred, max_basis);
  if (pca.basis.cols() == 0) return invalid("the training frames are all identical: there is no motion to model");
  const int M = o.basis_size > 0 ? std::min<int>(o.basis_size, static_cast<int>(pca.basis.cols()))
                                 : choose_basis_size(centred, pca, D, 0.5 * o.error_bound, chosen_cap);
  Subspace subspace{mean, pca.basis.leftCols(M), pca.singular_values.head(M)};

  // Key points (2007 §2.2), seeded with fiducials and the optional sparse grid.
  KeyPointOptions key_options;
  key_options.channel_count = D;
  key_options.block_size = o.block_size;
  key_options.error_bound = o.error_bound;
  key_options.max_key_points = o.max_key_points;
  key_options.candidate_count = static_cast<int>(control_points);
  key_options.progress = o.progress;
  key_options.seed_points = o.fiducial_points;
  if (o.grid_cells > 0) {
    PointMatrix positions = o.positions;
    if (positions.rows() == 0) {
      if (D != 3) return invalid("grid_cells with channels ≠ 3 needs explicit positions");
      positions = Eigen::Map<const PointMatrix>(mean.head(control_rows).cast<float>().eval().data(), control_points, 3);
    }
    if (positions.rows() != control_points) {
      return invalid("positions must have one row per control point (" + std::to_string(control_points) + ")");
    }
    for (int seed : grid_seeds(positions, o.grid_cells)) key_options.seed_points.push_back(seed);
  }
  auto selection = select_key_points(centred, subspace.basis, key_options);
  if (!selection) return selection.error();
  ANIMSPACE_RETURN_IF_ERROR(assemble(subspace, control_rows, cross, selection->key_points, model));

  // Regions for local fail-through (the keys index the same points only without cross).
  if (!cross && o.region_count > 0) {
    Regions regions = cluster_regions(subspace.basis, subspace.sigma, D, model.key_points, o.region_count);
    model.region_count = regions.count;
    model.point_regions = std::move(regions.point_regions);
    model.key_regions = std::move(regions.key_regions);
    model.region_weights = soft_region_weights(motion_signatures(subspace.basis, subspace.sigma, D),
                                               model.point_regions, model.region_count);
  }

  // ε from held-out training frames only: retrain the subspace without each fold (same keys,
  // same M), evaluate its frames through the runtime, and record how far the true max point
  // error can exceed e_key. ε_min = tolerance / (largest ratio) flags every such frame whose
  // error passes the tolerance; ε_max = ratio·ε_min gives the transition zone.
  double worst_ratio = 0;
  int calibration_frames = 0;
  const int folds = static_cast<int>(std::min<long>(std::max(o.calibration_folds, 2), F));
  for (int fold = 0; fold < folds; ++fold) {
    std::vector<long> train_columns, held_out;
    for (long f = 0; f < F; ++f) (f % folds == fold ? held_out : train_columns).push_back(f);
    // M < F must hold in the fold too; a fold with fewer frames uses a smaller subspace.
    const int fold_basis = static_cast<int>(std::min<long>(M, static_cast<long>(train_columns.size()) - 1));
    if (fold_basis < 1) continue;
    Eigen::MatrixXd T_fold(rows, static_cast<long>(train_columns.size()));
    for (size_t c = 0; c < train_columns.size(); ++c) T_fold.col(static_cast<long>(c)) = T.col(train_columns[c]);
    PmscModel fold_model = model;
    report_progress(o.progress, "calibration", fold, folds);
    if (!assemble(fit_subspace(T_fold, fold_basis), control_rows, cross, model.key_points, fold_model).ok()) continue;
    PoseEstimate estimate;
    for (long f : held_out) {
      // Held-out frames enter in the world frame, as at run time.
      Eigen::VectorXf control(control_rows);
      Eigen::VectorXf truth(rows - (cross ? control_rows : 0));
      control = control_frames.row(f).transpose();
      truth = cross ? Eigen::VectorXf(output_frames->row(f).transpose()) : control;
      evaluate(fold_model, gather_key_values(fold_model, control), estimate);
      const Eigen::MatrixXd residual = (truth - estimate.points).cast<double>();
      const double max_error = max_point_error(residual, D);
      ++calibration_frames;
      // A frame reproduced to rounding has a ratio of noise over noise; it says nothing.
      if (estimate.key_point_error < kNoiseFraction * o.error_tolerance) continue;
      worst_ratio = std::max(worst_ratio, max_error / std::max(estimate.key_point_error, 1e-30));
    }
  }
  // Without any usable frame fall back to the bound e_key ≤ max point error (the RMS over keys
  // never exceeds the largest key error), i.e. a ratio of 1.
  report_progress(o.progress, "calibration", folds, folds);
  model.epsilon.epsilon_min = o.error_tolerance / std::max(worst_ratio, 1.0);
  model.epsilon.epsilon_max = model.epsilon.epsilon_min * o.blend_zone_ratio;

  if (report) {
    report->frames = static_cast<int>(F);
    report->basis_size = M;
    report->key_points = model.key_point_count();
    report->max_residual_per_iteration = selection->max_residual;
    report->max_training_error = selection->max_residual.empty() ? 0 : selection->max_residual.back();
    report->converged = selection->converged;
    report->condition_number = model.condition_number;
    report->regularization = model.regularization;
    report->error_ratio = worst_ratio;
    report->calibration_frames = calibration_frames;
    report->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
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

double bounding_box_diagonal(const Eigen::Ref<const Eigen::VectorXf>& frame) {
  const Eigen::Map<const Eigen::Matrix3Xf> points(frame.data(), 3, frame.size() / 3);
  return static_cast<double>((points.rowwise().maxCoeff() - points.rowwise().minCoeff()).norm());
}

}  // namespace animspace::pmsc
