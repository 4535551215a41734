#include "core/pmsc/train.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string_view>
#include <tuple>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/common/parallel.h"
#include "core/container/model_container.h"
#include "core/pmsc/key_points.h"
#include "core/pmsc/pca.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/relative_point_errors.h"

namespace animspace::pmsc {
namespace {

// Frames that lie exactly in a rank-`rank` affine subspace: mean + B c_t, B random (N·3 × rank).
struct SyntheticSet {
  Eigen::VectorXd mean;
  Eigen::MatrixXd B;
  FrameMatrix frames;  // F × N·3
  Eigen::VectorXf frame(const Eigen::VectorXd& c) const { return (mean + B * c).cast<float>(); }
};

SyntheticSet exact_subspace(int points, int frames, int rank, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  SyntheticSet s;
  s.mean = Eigen::VectorXd::NullaryExpr(points * 3, [&] { return scale * normal(rng); });
  // Smooth-ish per-point motions so that points have distinct magnitudes.
  s.B = Eigen::MatrixXd::NullaryExpr(points * 3, rank, [&] { return 0.1 * scale * normal(rng); });
  s.frames.resize(frames, points * 3);
  for (int f = 0; f < frames; ++f) {
    const Eigen::VectorXd c = Eigen::VectorXd::NullaryExpr(rank, [&] { return normal(rng); });
    s.frames.row(f) = s.frame(c).transpose();
  }
  return s;
}

TrainingOptions options_for(double scale) {
  TrainingOptions o;
  o.error_bound = 1e-5 * scale;
  o.error_tolerance = 1e-3 * scale;
  o.region_count = 4;
  return o;
}

double max_abs(const Eigen::VectorXf& v) { return static_cast<double>(v.cwiseAbs().maxCoeff()); }

TEST(PmscTrain, ExactSubspaceReconstructsToRounding) {
  const auto data = exact_subspace(150, 30, 5, 1.0, 7);
  TrainingReport report;
  auto model = train(data.frames, options_for(1.0), &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_EQ(model->basis_size(), 5);
  EXPECT_TRUE(report.converged);
  EXPECT_GE(model->key_point_count() * 3, 5);

  // A pose never seen in training, but inside the subspace.
  std::mt19937 rng(99);
  std::normal_distribution<double> normal;
  const Eigen::VectorXd c = Eigen::VectorXd::NullaryExpr(5, [&] { return 2 * normal(rng); });
  const Eigen::VectorXf truth = data.frame(c);
  PoseEstimate estimate;
  evaluate(*model, gather_key_values(*model, truth), estimate);
  EXPECT_LT(max_abs(estimate.points - truth), 1e-4 * max_abs(truth));
  EXPECT_LT(estimate.key_point_error, 1e-4);
  EXPECT_EQ(decide(estimate.key_point_error, model->epsilon).status, CacheStatus::kHit);
}

// Frames in general position (rank F − 1 after centring) with M capped at half of them: the
// basis cannot project the training set within the bound, and the report says so. With every
// point a key, the keys' least squares is the orthogonal projection itself, so the training error
// equals the projection error computed here independently, by SVD of the centred frames.
TEST(PmscTrain, ABasisCappedByTheFramesReportsItsProjectionError) {
  const int points = 40, frames = 20;
  const auto data = exact_subspace(points, frames, frames, 1.0, 11);
  auto o = options_for(1.0);
  o.max_basis_fraction = 0.5;
  o.max_key_points = points;
  o.region_count = 0;
  TrainingReport report;
  auto model = train(data.frames, o, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  const int M = frames / 2;
  ASSERT_EQ(report.basis_size, M);
  EXPECT_TRUE(report.basis_capped);
  EXPECT_FALSE(report.converged);

  const Eigen::MatrixXd T = data.frames.cast<double>().transpose();  // N·3 × F
  const Eigen::MatrixXd centred = T.colwise() - T.rowwise().mean();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(centred, Eigen::ComputeThinU);
  const Eigen::MatrixXd U = svd.matrixU().leftCols(M);
  const Eigen::MatrixXd residual = centred - U * (U.transpose() * centred);
  double expected = 0;
  for (long f = 0; f < residual.cols(); ++f) {
    for (int i = 0; i < points; ++i) expected = std::max(expected, residual.col(f).segment<3>(3 * i).norm());
  }
  ASSERT_GT(expected, o.error_bound);
  EXPECT_NEAR(report.projection_error, expected, 1e-9 * expected + 1e-12);
  ASSERT_EQ(report.key_points, points);
  EXPECT_NEAR(report.max_training_error, expected, 1e-6 * expected);
}

// The same frames with M free to grow: not capped, and the projection meets half the bound.
TEST(PmscTrain, AnUncappedBasisProjectsWithinHalfTheBound) {
  const auto data = exact_subspace(40, 20, 6, 1.0, 12);
  TrainingReport report;
  auto model = train(data.frames, options_for(1.0), &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_FALSE(report.basis_capped);
  EXPECT_LE(report.projection_error, 0.5 * options_for(1.0).error_bound);
}

TEST(PmscTrain, KeyPointsAreDistinctAndFiducialsComeFirst) {
  const auto data = exact_subspace(120, 40, 12, 1.0, 3);
  auto o = options_for(1.0);
  o.fiducial_points = {17, 3, 17};  // a repeated seed counts once
  auto model = train(data.frames, o, nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  ASSERT_GE(model->key_points.size(), 2u);
  EXPECT_EQ(model->key_points[0], 17);
  EXPECT_EQ(model->key_points[1], 3);
  const std::set<int> unique(model->key_points.begin(), model->key_points.end());
  EXPECT_EQ(unique.size(), model->key_points.size());
}

TEST(PmscTrain, ScaleRobustness) {
  // The same data ×1e-4 and ×1e4 (with bounds scaled alike) gives the same keys and the same
  // relative reconstruction.
  std::vector<int> reference_keys;
  for (double scale : {1.0, 1e-4, 1e4}) {
    const auto data = exact_subspace(100, 25, 4, scale, 11);
    auto model = train(data.frames, options_for(scale), nullptr);
    ASSERT_TRUE(model.ok()) << scale << ": " << model.error().message;
    if (reference_keys.empty()) reference_keys = model->key_points;
    EXPECT_EQ(model->key_points, reference_keys) << "scale " << scale;
    const Eigen::VectorXf truth = data.frames.row(3).transpose();
    PoseEstimate estimate;
    evaluate(*model, gather_key_values(*model, truth), estimate);
    EXPECT_LT(max_abs(estimate.points - truth) / max_abs(truth), 1e-4) << "scale " << scale;
  }
}

TEST(PmscTrain, BasisMustBeSmallerThanTheFrameCount) {
  const auto data = exact_subspace(50, 10, 3, 1.0, 1);
  auto o = options_for(1.0);
  o.basis_size = 10;
  auto model = train(data.frames, o, nullptr);
  ASSERT_FALSE(model.ok());
  EXPECT_EQ(model.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(model.error().message.find("basis_size"), std::string::npos);
  EXPECT_NE(model.error().message.find("M < F"), std::string::npos);
}

TEST(PmscTrain, BadInputIsRefusedWithTheReason) {
  auto data = exact_subspace(50, 10, 3, 1.0, 1);
  data.frames(2, 7) = std::numeric_limits<float>::quiet_NaN();
  auto nan = train(data.frames, options_for(1.0), nullptr);
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(nan.error().message.find("NaN"), std::string::npos);

  const FrameMatrix one_frame = FrameMatrix::Ones(1, 30);
  EXPECT_FALSE(train(one_frame, options_for(1.0), nullptr).ok());

  const FrameMatrix still = FrameMatrix::Ones(5, 30);
  auto motionless = train(still, options_for(1.0), nullptr);
  ASSERT_FALSE(motionless.ok());
  EXPECT_NE(motionless.error().message.find("identical"), std::string::npos);

  auto o = options_for(1.0);
  o.error_bound = 0;
  EXPECT_FALSE(train(exact_subspace(50, 10, 3, 1.0, 1).frames, o, nullptr).ok());
}

TEST(PmscTrain, ColourChannelsWork) {
  // D = 1 and D = 4 are just different point sizes.
  for (int D : {1, 4}) {
    std::mt19937 rng(5);
    std::normal_distribution<double> normal;
    const int N = 80, F = 20, rank = 3;
    const Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(N * D, rank, [&] { return normal(rng); });
    FrameMatrix frames(F, N * D);
    for (int f = 0; f < F; ++f) {
      frames.row(f) = (B * Eigen::VectorXd::NullaryExpr(rank, [&] { return normal(rng); })).cast<float>().transpose();
    }
    auto o = options_for(1.0);
    o.channel_count = D;
    auto model = train(frames, o, nullptr);
    ASSERT_TRUE(model.ok()) << model.error().message;
    EXPECT_EQ(model->channel_count, D);
    EXPECT_EQ(model->point_count, N);
    EXPECT_GE(model->key_point_count() * D, rank);
  }
}

TEST(PmscTrain, RigidAlignmentRemovesRoomScaleMotion) {
  // A shape that deforms in a 2-D subspace while it moves and turns across the room: without
  // alignment the motion is non-linear in the points; with it the subspace is exact.
  const auto shape = exact_subspace(120, 40, 2, 1.0, 21);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> angle(-1.5, 1.5), offset(-20, 20);
  auto rigid = [&](const Eigen::VectorXf& frame) {
    const Eigen::Matrix3f R =
        Eigen::AngleAxisd(angle(rng), Eigen::Vector3d(0.2, 1, 0.1).normalized()).toRotationMatrix().cast<float>();
    const Eigen::Vector3f t(static_cast<float>(offset(rng)), 0, static_cast<float>(offset(rng)));
    Eigen::VectorXf out = frame;
    Eigen::Map<Eigen::Matrix3Xf> points(out.data(), 3, out.size() / 3);
    points = (R * points).colwise() + t;
    return out;
  };
  FrameMatrix moving(40, shape.frames.cols());
  for (int f = 0; f < 40; ++f) moving.row(f) = rigid(shape.frames.row(f).transpose()).transpose();
  Eigen::VectorXd c(2);
  c << 0.7, -1.1;
  const Eigen::VectorXf test = rigid(shape.frame(c));

  // Same budget for both: a rigid motion multiplies the dimension of the frame set by ~9, so a
  // small basis can only hold it once the motion is removed.
  auto o = options_for(1.0);
  o.basis_size = 6;
  o.max_key_points = 40;
  o.remove_rigid_motion = true;
  auto aligned = train(moving, o, nullptr);
  ASSERT_TRUE(aligned.ok()) << aligned.error().message;
  EXPECT_TRUE(aligned->aligned);
  o.remove_rigid_motion = false;
  auto plain = train(moving, o, nullptr);
  ASSERT_TRUE(plain.ok()) << plain.error().message;

  PoseEstimate a, p;
  evaluate(*aligned, gather_key_values(*aligned, test), a);
  evaluate(*plain, gather_key_values(*plain, test), p);
  const double aligned_error = max_abs(a.points - test);
  const double plain_error = max_abs(p.points - test);
  // Procrustes absorbs a little deformation into the estimated rotation, so "exact" is ~1e-3 of
  // the shape's 20-unit extent.
  EXPECT_LT(aligned_error, 1e-2) << "plain " << plain_error;
  EXPECT_GT(plain_error, 10 * aligned_error);
}

TEST(PmscTrain, CrossPmscDrivesAnotherPointSet) {
  // Control and output points are two linear views of the same 3 pose parameters.
  std::mt19937 rng(8);
  std::normal_distribution<double> normal;
  const int F = 30, rank = 3, Nc = 40, No = 90;
  const Eigen::MatrixXd Bc = Eigen::MatrixXd::NullaryExpr(Nc * 3, rank, [&] { return normal(rng); });
  const Eigen::MatrixXd Bo = Eigen::MatrixXd::NullaryExpr(No * 3, rank, [&] { return normal(rng); });
  FrameMatrix control(F, Nc * 3), output(F, No * 3);
  for (int f = 0; f < F; ++f) {
    const Eigen::VectorXd c = Eigen::VectorXd::NullaryExpr(rank, [&] { return normal(rng); });
    control.row(f) = (Bc * c).cast<float>().transpose();
    output.row(f) = (Bo * c).cast<float>().transpose();
  }
  auto model = train_cross(control, output, options_for(1.0), nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_TRUE(model->cross);
  EXPECT_EQ(model->point_count, No);
  EXPECT_EQ(model->control_point_count, Nc);
  for (int k : model->key_points) EXPECT_LT(k, Nc);

  Eigen::VectorXd c(rank);
  c << 1.5, -0.3, 0.8;
  const Eigen::VectorXf control_pose = (Bc * c).cast<float>();
  const Eigen::VectorXf truth = (Bo * c).cast<float>();
  PoseEstimate estimate;
  evaluate(*model, gather_key_values(*model, control_pose), estimate);
  EXPECT_LT(max_abs(estimate.points - truth), 1e-4 * max_abs(truth));
}

TEST(PmscTrain, EpsilonComesFromHeldOutFramesAndTheZoneRatio) {
  // Data outside any small subspace (random frames): held-out errors are large.
  std::mt19937 rng(2);
  std::normal_distribution<double> normal;
  FrameMatrix frames = FrameMatrix::NullaryExpr(24, 60 * 3, [&] { return static_cast<float>(normal(rng)); });
  auto o = options_for(1.0);
  o.error_bound = 0.5;
  o.error_tolerance = 0.1;
  o.max_key_points = 30;
  TrainingReport report;
  auto model = train(frames, o, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_GT(report.calibration_frames, 0);
  // Every held-out frame of random data is far over the tolerance; the rule extrapolates each to
  // just over it (calibration.h), so every sample is a bad one and ε_min never exceeds the
  // estimate of any sample scaled to the tolerance.
  EXPECT_EQ(model->calibration.over_tolerance, report.calibration_frames);
  EXPECT_EQ(model->calibration.bad_samples, report.calibration_frames);
  const CalibrationSamples& s = model->calibration.samples;
  const Eigen::VectorXd scaled = s.error_estimates(model->key_weight).cwiseProduct(s.max_errors.cwiseInverse()) * 0.1;
  EXPECT_GE(model->epsilon.epsilon_min, scaled.minCoeff());
  EXPECT_LT(model->epsilon.epsilon_min, scaled.maxCoeff());
  EXPECT_NEAR(model->epsilon.epsilon_min, 0.1 / report.error_ratio, 1e-12);
  EXPECT_NEAR(model->epsilon.epsilon_max, 1.5 * model->epsilon.epsilon_min, 1e-12);
}

TEST(PmscIo, ContainerRoundTripServesTheSameEstimates) {
  const auto data = exact_subspace(60, 20, 4, 1.0, 13);
  TrainingReport report;
  auto model = train(data.frames, options_for(1.0), &report);
  ASSERT_TRUE(model.ok());
  TriangleMesh mesh;
  mesh.V = Eigen::Map<const PointMatrix>(data.frames.row(0).data(), 60, 3);
  const auto container = make_container(mesh, data.frames, nullptr, *model, report, "synthetic");
  auto parsed = container::parse(container::serialize(container), "memory");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_EQ(parsed->metadata_value("kind"), "pmsc");
  auto loaded = load(*parsed, "memory");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->key_points, model->key_points);
  EXPECT_EQ(loaded->point_regions, model->point_regions);
  EXPECT_EQ(loaded->epsilon.epsilon_min, model->epsilon.epsilon_min);
  const Eigen::VectorXf pose = data.frames.row(5).transpose();
  PoseEstimate a, b;
  evaluate(*model, gather_key_values(*model, pose), a);
  evaluate(*loaded, gather_key_values(*loaded, pose), b);
  EXPECT_TRUE(a.points.isApprox(b.points, 1e-6f));

  // A damaged model is refused with the section named.
  container::ModelContainer broken = *parsed;
  broken.set_matrix("pmsc.key_mean", container::Float64Matrix(container::Float64Matrix::Zero(1, 2)));
  auto refused = load(broken, "broken.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("broken.anim"), std::string::npos);
  EXPECT_NE(refused.error().message.find("key_mean"), std::string::npos);
}

}  // namespace
}  // namespace animspace::pmsc

namespace animspace::pmsc {
namespace {

// Progress (for the command line's bars): key points never pass the budget and never go back,
// every calibration fold is announced, and the last call says the work is complete.
TEST(PmscTrain, ReportsProgressThroughKeySelectionAndCalibration) {
  const auto data = exact_subspace(150, 30, 5, 1.0, 7);
  TrainingOptions o = options_for(1.0);
  o.calibration_folds = 4;
  std::vector<std::tuple<std::string, int64_t, int64_t>> calls;
  o.progress = [&](std::string_view stage, int64_t done, int64_t total) {
    calls.emplace_back(std::string(stage), done, total);
  };
  TrainingReport report;
  ASSERT_TRUE(train(data.frames, o, &report).ok());
  int64_t keys_before = 0;
  std::vector<int64_t> folds;
  for (const auto& [stage, done, total] : calls) {
    if (stage == "key points") {
      EXPECT_EQ(total, o.max_key_points);
      EXPECT_GE(done, keys_before);
      EXPECT_LE(done, total);
      keys_before = done;
    } else {
      ASSERT_EQ(stage, "calibration");
      // 30 frames, four folds: four interleaved, four sparse, and blocks of 4, 8 and 16 frames dealt
      // to four, four and two folds.
      EXPECT_EQ(total, 18);
      folds.push_back(done);
    }
  }
  EXPECT_EQ(keys_before, report.key_points);
  std::vector<int64_t> expected(19);
  std::iota(expected.begin(), expected.end(), 0);
  EXPECT_EQ(folds, expected);
}


// Issue #38 item 3: frames = a rank-r affine subspace + isotropic noise (N·D ≫ F, as PMSC data
// is). Every held-out frame's projection error onto a fold's first k ≥ r directions is its noise
// (less the ~k/R share a direction unrelated to it removes), and for k < r it also misses a
// signal direction holding far more energy than the noise: the smallest k within 5% of the best
// is r, at any scale. The curve at r is checked against the noise itself, computed independently.
struct NoisySet {
  FrameMatrix frames;
  double noise_fraction = 0;  // ‖noise‖ / ‖frames − their mean‖ over all frames
};

NoisySet noisy_subspace(int points, int frames, int rank, double noise, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  const long R = 3L * points;
  const Eigen::VectorXd mean = Eigen::VectorXd::NullaryExpr(R, [&] { return scale * normal(rng); });
  const Eigen::MatrixXd B = Eigen::MatrixXd::NullaryExpr(R, rank, [&] { return 0.1 * scale * normal(rng); });
  Eigen::MatrixXd clean(R, frames), noisy(R, frames);
  for (int f = 0; f < frames; ++f) {
    clean.col(f) = mean + B * Eigen::VectorXd::NullaryExpr(rank, [&] { return normal(rng); });
    noisy.col(f) = clean.col(f) + Eigen::VectorXd::NullaryExpr(R, [&] { return noise * scale * normal(rng); });
  }
  NoisySet s;
  s.frames = noisy.transpose().cast<float>();
  const Eigen::MatrixXd centred = noisy.colwise() - noisy.rowwise().mean();
  s.noise_fraction = (noisy - clean).norm() / centred.norm();
  return s;
}

TEST(PmscTrain, AHeldOutBasisIsTheRankTheFramesSupport) {
  for (double scale : {1e-4, 1.0, 1e4}) {
    const int rank = 6;
    const NoisySet data = noisy_subspace(1000, 80, rank, 0.002, scale, 21);
    TrainingOptions o = options_for(scale);
    o.held_out_basis_slack = 0.05;
    TrainingReport report;
    auto model = train(data.frames, o, &report);
    ASSERT_TRUE(model.ok()) << model.error().message;
    EXPECT_EQ(model->basis_size(), rank) << "scale " << scale;
    EXPECT_EQ(report.basis_size, rank);
    // The curve: one value per k = 0 … the cap (0.7 · 80 = 56), 1 at k = 0 (nothing projected).
    ASSERT_EQ(report.held_out_relative_rms.size(), 57u);
    EXPECT_NEAR(report.held_out_relative_rms[0], 1.0, 1e-9);
    const double best =
        *std::min_element(report.held_out_relative_rms.begin() + 1, report.held_out_relative_rms.end());
    EXPECT_LE(report.held_out_relative_rms[rank], 1.05 * best);
    EXPECT_GT(report.held_out_relative_rms[rank - 1], 1.05 * best);
    // At k = r what is left is the noise: within 10% of its share of the frames' energy (the
    // fold's mean and the r directions hold a few of its R = 3000 dimensions).
    EXPECT_NEAR(report.held_out_relative_rms[rank], data.noise_fraction, 0.1 * data.noise_fraction) << "scale " << scale;
  }
}

// With nothing but noise around the mean no direction generalises: the held-out error hardly
// moves with k (each direction removes ~1/R of a held-out frame's energy), so M is 1.
TEST(PmscTrain, AHeldOutBasisOfNoiseAloneIsOneVector) {
  const NoisySet data = noisy_subspace(1000, 60, 0, 0.01, 1.0, 5);
  TrainingOptions o = options_for(1.0);
  o.held_out_basis_slack = 0.05;
  TrainingReport report;
  auto model = train(data.frames, o, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_EQ(model->basis_size(), 1);
  EXPECT_GT(report.held_out_relative_rms.back(), 0.95);
}

TEST(PmscTrain, AHeldOutBasisSlackMustBeANonNegativeNumber) {
  const auto data = exact_subspace(50, 20, 3, 1.0, 3);
  TrainingOptions o = options_for(1.0);
  o.held_out_basis_slack = -0.1;
  auto model = train(data.frames, o, nullptr);
  ASSERT_FALSE(model.ok());
  EXPECT_NE(model.error().message.find("held_out_basis_slack"), std::string::npos);
}

// What the held-out key budget measures, worked by hand: frames in the span of a basis, one of
// them with a bump at a point that is not a key. The keys' rows do not see the bump, so the
// coordinates are exact and the reconstruction misses the bump alone: its norm is that frame's
// worst point, and every other frame's is rounding. 70 frames: more than one block of 32.
TEST(PmscKeyPoints, TheWorstPointOfAKeyReconstructionIsWhatNoKeySees) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  const int points = 60, M = 4, frames = 70;
  const Eigen::MatrixXd basis = Eigen::MatrixXd::NullaryExpr(3 * points, M, [&] { return normal(rng); });
  Eigen::MatrixXd X = basis * Eigen::MatrixXd::NullaryExpr(M, frames, [&] { return normal(rng); });
  const std::vector<int> keys = {0, 7, 19, 33, 41};
  const Eigen::Vector3d bump(0.3, -0.4, 1.2);
  X.col(45).segment<3>(3 * 50) += bump;
  const Eigen::VectorXd worst = key_reconstruction_worst_errors(X, basis, keys, 3);
  ASSERT_EQ(worst.size(), frames);
  for (long f = 0; f < frames; ++f) {
    if (f == 45) {
      EXPECT_NEAR(worst(f), bump.norm(), 1e-10);
    } else {
      EXPECT_LT(worst(f), 1e-10) << "frame " << f;
    }
  }
  // A bump under a key moves the coordinates instead: the error spreads, and the bumped point
  // itself is reconstructed with part of it.
  X.col(3).segment<3>(3 * 19) += bump;
  EXPECT_GT(key_reconstruction_worst_errors(X, basis, keys, 3)(3), 1e-3);
}

// Issue #52 item 2, the held-out key budget. Frames exactly in a rank-5 subspace: keys chosen on
// either half of the frames reproduce the other half to rounding, within the selection's own
// bound at the first rung, so the rule keeps where the selection stopped.
TEST(PmscTrain, TheHeldOutKeyRuleKeepsTheStopWhenKeysReproduceFramesTheyNeverSaw) {
  const auto data = exact_subspace(500, 40, 5, 1.0, 23);
  TrainingOptions o = options_for(1.0);
  o.held_out_key_slack = 0.05;
  TrainingReport report;
  auto model = train(data.frames, o, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  ASSERT_EQ(report.key_budget_counts.size(), 1u);
  EXPECT_EQ(report.key_budget_counts[0], model->key_point_count());
  EXPECT_LE(report.key_budget_errors[0], o.error_bound);
  o.held_out_key_slack = 0;
  auto fixed = train(data.frames, o, nullptr);
  ASSERT_TRUE(fixed.ok()) << fixed.error().message;
  EXPECT_EQ(fixed->key_points, model->key_points);
}

// A rank-4 subspace plus noise with M = 10: six of the directions are the training frames' noise,
// and their coordinates, estimated from the keys' noisy values, carry noise into every point;
// each key more averages it down. On frames the keys never saw, the worst point falls with the
// count, so from a budget of 12 the rule climbs its ladder (√2 apart, up to 8% of the 1,000
// points) and serves more keys; and fresh frames of the same motion, which neither model saw,
// are reconstructed better than by the 12 keys of slack 0.
TEST(PmscTrain, TheHeldOutKeyRuleAddsKeysWhileTheyLowerTheWorstPointOnNewFrames) {
  const NoisySet data = noisy_subspace(1000, 90, 4, 0.01, 1.0, 31);
  const FrameMatrix training = data.frames.topRows(60), fresh = data.frames.bottomRows(30);
  TrainingOptions o = options_for(1.0);
  o.basis_size = 10;
  o.max_key_points = 12;
  o.held_out_key_slack = 0.05;
  o.region_count = 0;
  TrainingReport report;
  auto ruled = train(training, o, &report);
  ASSERT_TRUE(ruled.ok()) << ruled.error().message;
  TrainingOptions fixed_options = o;
  fixed_options.held_out_key_slack = 0;
  TrainingReport fixed_report;
  auto fixed = train(training, fixed_options, &fixed_report);
  ASSERT_TRUE(fixed.ok()) << fixed.error().message;
  EXPECT_EQ(fixed->key_point_count(), 12);
  EXPECT_TRUE(fixed_report.key_budget_counts.empty());

  const std::vector<int>& counts = report.key_budget_counts;
  const std::vector<double>& errors = report.key_budget_errors;
  ASSERT_GE(counts.size(), 2u);
  ASSERT_EQ(errors.size(), counts.size());
  EXPECT_EQ(counts[0], 12);
  for (size_t i = 1; i < counts.size(); ++i) {
    EXPECT_EQ(counts[i], static_cast<int>(std::ceil(std::sqrt(2.0) * counts[i - 1])));
    EXPECT_LE(counts[i], 80);
  }
  const double best = *std::min_element(errors.begin(), errors.end());
  const auto chosen = std::find(counts.begin(), counts.end(), ruled->key_point_count());
  ASSERT_NE(chosen, counts.end());
  const size_t at = static_cast<size_t>(chosen - counts.begin());
  EXPECT_GT(at, 0u);
  EXPECT_LE(errors[at], (1 + o.held_out_key_slack) * best);
  for (size_t i = 0; i < at; ++i) EXPECT_GT(errors[i], (1 + o.held_out_key_slack) * best);

  const auto mean_worst_point = [&](const PmscModel& model) {
    double sum = 0;
    PoseEstimate estimate;
    for (long f = 0; f < fresh.rows(); ++f) {
      const Eigen::VectorXf truth = fresh.row(f).transpose();
      evaluate(model, gather_key_values(model, truth), estimate);
      const Eigen::VectorXf residual = truth - estimate.points;
      sum += static_cast<double>(Eigen::Map<const Eigen::Matrix3Xf>(residual.data(), 3, residual.size() / 3)
                                     .colwise()
                                     .norm()
                                     .maxCoeff());
    }
    return sum / static_cast<double>(fresh.rows());
  };
  EXPECT_LT(mean_worst_point(*ruled), mean_worst_point(*fixed));
}

TEST(PmscTrain, AHeldOutKeySlackMustBeANonNegativeNumber) {
  const auto data = exact_subspace(50, 20, 3, 1.0, 3);
  TrainingOptions o = options_for(1.0);
  o.held_out_key_slack = std::nan("");
  auto model = train(data.frames, o, nullptr);
  ASSERT_FALSE(model.ok());
  EXPECT_NE(model.error().message.find("held_out_key_slack"), std::string::npos);
}

// Issue #38 item 3: the calibration folds run on every core, and the model is the same on one
// thread and on two (each fold is computed alone; the samples are joined in fold order). The
// key selection's residual passes split their blocks of kResidualBlockPoints points across the
// cores too: 2,500 points make three blocks, the last one short.
TEST(PmscTrain, TheModelIsTheSameOnOneThreadAndOnTwo) {
  static_assert(2 * kResidualBlockPoints < 2500 && 2500 < 3 * kResidualBlockPoints);
  const NoisySet data = noisy_subspace(2500, 48, 5, 0.01, 1.0, 9);
  TrainingOptions o = options_for(1.0);
  o.held_out_basis_slack = 0.05;
  std::vector<PmscModel> models;
  for (int threads : {1, 2}) {
    set_thread_limit(threads);
    auto model = train(data.frames, o, nullptr);
    set_thread_limit(0);
    ASSERT_TRUE(model.ok()) << model.error().message;
    models.push_back(*std::move(model));
  }
  const PmscModel& a = models[0];
  const PmscModel& b = models[1];
  EXPECT_EQ(a.basis, b.basis);
  EXPECT_EQ(a.mean, b.mean);
  EXPECT_EQ(a.key_points, b.key_points);
  EXPECT_EQ(a.check_points, b.check_points);
  ASSERT_GT(a.calibration.samples.key_point_errors.size(), 0);
  EXPECT_EQ(a.calibration.samples.key_point_errors, b.calibration.samples.key_point_errors);
  EXPECT_EQ(a.calibration.samples.max_errors, b.calibration.samples.max_errors);
  EXPECT_EQ(a.calibration.samples.region_max_errors, b.calibration.samples.region_max_errors);
  EXPECT_EQ(a.calibration.samples.fold_family, b.calibration.samples.fold_family);
  EXPECT_EQ(a.epsilon.epsilon_min, b.epsilon.epsilon_min);
  EXPECT_EQ(a.epsilon.epsilon_max, b.epsilon.epsilon_max);
}

// Issue #53 item 2: past a memory budget only some held-out sets keep every point's error; the
// check points are chosen on them, and the other sets' samples are measured at the chosen points
// only. Frames of a rank-3 motion plus a jiggle at a few points of its own per frame, amplitudes
// halving from point to point (the basis has the motion only, so the jiggle is what every
// held-out frame gets wrong, and its largest points are where check points belong on any share
// of the samples). Trained with the whole errors kept and with a budget that keeps one set per
// fold family: the same check points, and each sample's e_check the same to the 16-bit step of
// the whole errors (exact at the chosen points, where the whole errors round down).
TEST(PmscTrain, CheckPointsChosenOnSomeHeldOutSetsMeasureEverySampleAtThem) {
  constexpr int kPoints = 400;
  SyntheticSet data = exact_subspace(kPoints, 60, 3, 1.0, 17);
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  for (long f = 0; f < data.frames.rows(); ++f) {
    for (int j = 0; j < 8; ++j) {
      data.frames(f, 3 * (23 + 47 * j) + 1) += static_cast<float>(std::ldexp(0.5, -j) * normal(rng));
    }
  }
  TrainingOptions o = options_for(1.0);
  o.basis_size = 3;
  o.max_key_points = 10;
  o.region_count = 0;
  o.error_tolerance = 0.01;
  TrainingReport whole_report, budget_report;
  auto whole = train(data.frames, o, &whole_report);
  ASSERT_TRUE(whole.ok()) << whole.error().message;
  o.point_error_budget_bytes = 1;
  auto budget = train(data.frames, o, &budget_report);
  ASSERT_TRUE(budget.ok()) << budget.error().message;

  EXPECT_EQ(whole_report.check_point_samples, whole_report.calibration_frames) << "a small model keeps them all";
  EXPECT_GT(budget_report.check_point_samples, 0);
  EXPECT_LT(budget_report.check_point_samples, budget_report.calibration_frames / 2);
  ASSERT_EQ(whole->key_points, budget->key_points);
  const CalibrationSamples& a = whole->calibration.samples;
  const CalibrationSamples& b = budget->calibration.samples;
  ASSERT_EQ(a.max_errors, b.max_errors) << "the same folds judge the same frames";
  std::vector<int> a_checks = whole->check_points, b_checks = budget->check_points;
  std::sort(a_checks.begin(), a_checks.end());
  std::sort(b_checks.begin(), b_checks.end());
  ASSERT_EQ(a_checks.size(), 2u);
  ASSERT_EQ(a_checks, b_checks) << "the fixture's largest jiggles are found on any share of the samples";
  long seen = 0;
  for (long i = 0; i < a.size(); ++i) {
    const double step = a.max_errors(i) / RelativePointErrors::kScale;
    EXPECT_GE(b.check_point_errors(i), a.check_point_errors(i) - 1e-12) << "sample " << i;
    EXPECT_LE(b.check_point_errors(i), a.check_point_errors(i) + 1.001 * step + 1e-12) << "sample " << i;
    seen += b.check_point_errors(i) > 0.1 * b.max_errors(i) ? 1 : 0;
  }
  EXPECT_GT(seen, a.size() / 2) << "the check points see most samples' jiggle";
}

}  // namespace
}  // namespace animspace::pmsc
