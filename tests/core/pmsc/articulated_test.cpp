// The articulated subspace (issue #51, core/pmsc/articulated.h): its skinning columns against the
// linear blend formula written out, and a model trained on a skinned arm that meets motion past
// every training pose — where a position PCA cannot follow — against the rig's own poses.
#include "core/pmsc/articulated.h"

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "core/common/kernels.h"
#include "core/common/parallel.h"
#include "core/container/model_container.h"
#include "core/demo/bending_arm.h"
#include "core/pmsc/articulated_rig.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/retrain.h"
#include "core/pmsc/subspace.h"
#include "core/pmsc/train.h"

namespace animspace::pmsc {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

// L p against Σ_j w_ij M_j [p̂_i − c_j; 1] for random weights, rest points, centres and affine
// maps: the columns' layout (12 per bone, row-major 3 × 4) is what the coordinates mean.
TEST(ArticulatedSubspace, SkinningColumnsPoseByTheLinearBlendFormula) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> uniform(-1, 1);
  const int N = 9, B = 3;
  Eigen::MatrixX3d rest(N, 3), centres(B, 3);
  for (int i = 0; i < N; ++i) rest.row(i) << uniform(random), uniform(random), uniform(random);
  for (int j = 0; j < B; ++j) centres.row(j) << uniform(random), uniform(random), uniform(random);
  // Point i has bones (i mod 3) + 1 and, for odd i, also the next one; the root (bone 0) on
  // point 0 carries no columns.
  animation_space::InfluenceSets influences;
  std::vector<double> w;
  for (int i = 0; i < N; ++i) {
    if (i == 0) {
      influences.bones.push_back(0);
      w.push_back(0.25);
    }
    const int first = i % 3 + 1;
    influences.bones.push_back(first);
    if (i % 2 == 1) {
      influences.bones.push_back(first % 3 + 1);
      w.push_back(0.3);
      w.push_back(0.7);
    } else {
      w.push_back(i == 0 ? 0.75 : 1.0);
    }
    influences.offsets.push_back(static_cast<int32_t>(influences.bones.size()));
  }
  const Eigen::VectorXd weights = Eigen::Map<const Eigen::VectorXd>(w.data(), static_cast<long>(w.size()));
  std::vector<Eigen::Matrix<double, 3, 4>> maps(B);
  Eigen::VectorXd p(kBoneCoordinates * B);
  for (int j = 0; j < B; ++j) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        maps[static_cast<size_t>(j)](r, c) = uniform(random);
        p(kBoneCoordinates * j + 4 * r + c) = maps[static_cast<size_t>(j)](r, c);
      }
    }
  }
  const Eigen::VectorXd posed = skinning_columns(rest, influences, weights, B, centres) * p;
  for (int i = 0; i < N; ++i) {
    Eigen::Vector3d expected = Eigen::Vector3d::Zero();
    for (int k = influences.begin(i); k < influences.end(i); ++k) {
      const int bone = influences.bones[static_cast<size_t>(k)];
      if (bone == 0) continue;
      Eigen::Vector4d h;
      h << (rest.row(i) - centres.row(bone - 1)).transpose(), 1.0;
      expected += weights(k) * maps[static_cast<size_t>(bone - 1)] * h;
    }
    EXPECT_LT((posed.segment<3>(3 * i) - expected).norm(), 1e-12) << "point " << i;
  }
}

// Frames of the bending arm's plain linear blend skinning, one row each.
FrameMatrix arm_frames(const demo::ArmRig& rig, const std::vector<demo::ArmPose>& poses) {
  FrameMatrix frames(static_cast<long>(poses.size()), 3 * rig.rest.V.rows());
  for (size_t f = 0; f < poses.size(); ++f) {
    const PointMatrix posed = demo::pose_linear_blend(poses[f], rig);
    frames.row(static_cast<long>(f)) = Eigen::Map<const Eigen::RowVectorXf>(posed.data(), posed.size());
  }
  return frames;
}

std::vector<demo::ArmPose> random_poses(int count, double max_elbow, double min_elbow, double max_swing,
                                        uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> elbow(min_elbow, max_elbow), swing(-max_swing, max_swing);
  std::vector<demo::ArmPose> poses(static_cast<size_t>(count));
  for (demo::ArmPose& pose : poses) {
    pose.elbow_angle_rad = elbow(random);
    pose.shoulder_angle_rad = swing(random);
  }
  return poses;
}

// Worst point error of the model's estimate from each frame's key values, over the frames.
double worst_point_error(const PmscModel& model, const FrameMatrix& frames) {
  double worst = 0;
  PoseEstimate estimate;
  for (long f = 0; f < frames.rows(); ++f) {
    const Eigen::VectorXf frame = frames.row(f).transpose();
    evaluate(model, gather_key_values(model, frame), estimate);
    const Eigen::VectorXf residual = frame - estimate.points;
    worst = std::max(worst, static_cast<double>(
                                Eigen::Map<const Eigen::Matrix3Xf>(residual.data(), 3, residual.size() / 3)
                                    .colwise()
                                    .norm()
                                    .maxCoeff()));
  }
  return worst;
}

struct ArmCase {
  demo::ArmRig rig = demo::make_arm_rig();
  // Trained on an elbow within 0–40° and a swing of ±10°; tested at 80–120° and ±30°: every test
  // pose is past every training pose, as a new shot is.
  FrameMatrix training = arm_frames(rig, random_poses(60, 40 * kDegree, 0, 10 * kDegree, 1));
  FrameMatrix new_shot = arm_frames(rig, random_poses(40, 120 * kDegree, 80 * kDegree, 30 * kDegree, 2));
  double diagonal = bounding_box_diagonal(training.row(0).transpose());

  TrainingOptions options(SubspaceKind kind) const {
    TrainingOptions o;
    o.subspace_kind = kind;
    o.error_bound = 0.0025 * diagonal;
    o.error_tolerance = 0.01 * diagonal;
    if (kind == SubspaceKind::kArticulated) {
      o.faces = rig.rest.F;
      o.bone_count = 2;  // the rig's own bones
    }
    return o;
  }
};

// The arm's frames are linear blend skinning with two bones: the articulated subspace contains
// every pose of it, trained or not, so a new shot is reconstructed from its keys (up to the
// decomposition's fit of the weights); the linear subspace, trained on the same frames, cannot
// bend the elbow further than it saw.
TEST(ArticulatedSubspace, ANewShotOfASkinnedArmStaysInsideIt) {
  const ArmCase arm;
  TrainingReport articulated_report;
  auto articulated = train(arm.training, arm.options(SubspaceKind::kArticulated), &articulated_report);
  ASSERT_TRUE(articulated.ok()) << articulated.error().message;
  auto linear = train(arm.training, arm.options(SubspaceKind::kLinear), nullptr);
  ASSERT_TRUE(linear.ok()) << linear.error().message;

  EXPECT_EQ(articulated->subspace_kind, SubspaceKind::kArticulated);
  EXPECT_EQ(articulated->bone_count, 2);
  EXPECT_EQ(articulated->basis_size(), 12 * 2 + articulated->residual_components);
  EXPECT_EQ(articulated_report.bones, 2);
  // Skinning alone fits the training frames: they are skinning.
  EXPECT_LT(articulated_report.skinning_rms, 1e-3 * arm.diagonal);

  const double articulated_error = worst_point_error(*articulated, arm.new_shot);
  const double linear_error = worst_point_error(*linear, arm.new_shot);
  EXPECT_LT(articulated_error, 0.01 * arm.diagonal) << "articulated " << articulated_error / arm.diagonal;
  EXPECT_GT(linear_error, 0.05 * arm.diagonal) << "linear " << linear_error / arm.diagonal;
  EXPECT_LT(articulated_error, 0.1 * linear_error);
}

TEST(ArticulatedSubspace, AModelFileKeepsItsKindAndOlderFilesAreLinear) {
  const ArmCase arm;
  auto model = train(arm.training, arm.options(SubspaceKind::kArticulated), nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  container::ModelContainer file;
  store(*model, file);
  auto loaded = load(file, "arm.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->subspace_kind, SubspaceKind::kArticulated);
  EXPECT_EQ(loaded->bone_count, model->bone_count);
  EXPECT_EQ(loaded->residual_components, model->residual_components);
  EXPECT_EQ(worst_point_error(*loaded, arm.new_shot), worst_point_error(*model, arm.new_shot));

  // A file whose counts disagree with its basis is refused, naming both.
  container::ModelContainer wrong = file;
  wrong.metadata()["pmsc.bone_count"] = std::to_string(model->bone_count + 1);
  auto refused = load(wrong, "wrong.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("wrong.anim"), std::string::npos) << refused.error().message;
  EXPECT_NE(refused.error().message.find("12·bones + residual components"), std::string::npos)
      << refused.error().message;
  // An unknown kind is refused, naming the key and the value.
  wrong = file;
  wrong.metadata()["pmsc.subspace_kind"] = "cubic";
  refused = load(wrong, "wrong.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("'pmsc.subspace_kind' should be linear or articulated, got 'cubic'"),
            std::string::npos)
      << refused.error().message;

  // A file written before issue #51 has no kind: it is linear.
  auto linear = train(arm.training, arm.options(SubspaceKind::kLinear), nullptr);
  ASSERT_TRUE(linear.ok());
  container::ModelContainer older;
  store(*linear, older);
  older.metadata().erase("pmsc.subspace_kind");
  auto old_loaded = load(older, "old.anim");
  ASSERT_TRUE(old_loaded.ok()) << old_loaded.error().message;
  EXPECT_EQ(old_loaded->subspace_kind, SubspaceKind::kLinear);

  // The training options round-trip the kind and its counts, for retraining.
  TrainingOptions options = arm.options(SubspaceKind::kArticulated);
  options.residual_components = 3;
  container::ModelContainer with_options;
  store_training_options(options, with_options);
  auto read = load_training_options(with_options, "m");
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(read->subspace_kind, SubspaceKind::kArticulated);
  EXPECT_EQ(read->bone_count, 2);
  EXPECT_EQ(read->residual_components, 3);
}

// `--subspace auto`: both kinds trained, the one within the tolerance more often on the held-out
// blocks kept; the fractions counted here from each model's own samples.
TEST(ArticulatedSubspace, AutoKeepsTheKindBetterOnHeldOutBlocksAndSaysWhy) {
  const ArmCase arm;
  // Sequential frames (the elbow bending further frame by frame), so that a held-out block is
  // motion the rest of the training did not show.
  std::vector<demo::ArmPose> sweep(48);
  for (size_t f = 0; f < sweep.size(); ++f) {
    sweep[f].elbow_angle_rad = 100 * kDegree * static_cast<double>(f) / 47;
    sweep[f].shoulder_angle_rad = 20 * kDegree * std::sin(0.2 * static_cast<double>(f));
  }
  const FrameMatrix frames = arm_frames(arm.rig, sweep);
  TrainingOptions options = arm.options(SubspaceKind::kArticulated);
  SubspaceChoice choice;
  TrainingReport report;
  auto model = train_best_kind(frames, options, &report, &choice);
  ASSERT_TRUE(model.ok()) << model.error().message;

  const auto block_fraction = [&](SubspaceKind kind) {
    TrainingOptions o = options;
    o.subspace_kind = kind;
    auto trained = train(frames, o, nullptr);
    EXPECT_TRUE(trained.ok());
    const CalibrationSamples& s = trained->calibration.samples;
    double within = 0, count = 0;
    for (long i = 0; i < s.size(); ++i) {
      if (s.fold_family[static_cast<size_t>(i)] != kBlockFold) continue;
      count += 1;
      within += s.max_errors(i) <= options.error_tolerance ? 1 : 0;
    }
    return within / count;
  };
  const double linear = block_fraction(SubspaceKind::kLinear);
  const double articulated = block_fraction(SubspaceKind::kArticulated);
  EXPECT_DOUBLE_EQ(choice.linear_block_within_tolerance, linear);
  EXPECT_DOUBLE_EQ(choice.articulated_block_within_tolerance, articulated);
  EXPECT_EQ(choice.kind, articulated > linear ? SubspaceKind::kArticulated : SubspaceKind::kLinear);
  EXPECT_EQ(model->subspace_kind, choice.kind);
  // The arm is skinning: its held-out blocks stay inside the articulated subspace.
  EXPECT_GT(articulated, linear);
  EXPECT_NE(choice.reason.find("held-out blocks"), std::string::npos) << choice.reason;
  EXPECT_EQ(report.bones, model->bone_count);
}

// The same frames and options give the same model, bit for bit, on one thread and on two: a
// retrain reproduces it, whatever machine runs it.
TEST(ArticulatedSubspace, TrainingIsDeterministic) {
  const ArmCase arm;
  TrainingOptions options = arm.options(SubspaceKind::kArticulated);
  options.bone_count = 0;  // by rule, 4 bones for the arm's 1154 points
  set_thread_limit(1);
  auto first = train(arm.training, options, nullptr);
  set_thread_limit(2);
  auto second = train(arm.training, options, nullptr);
  set_thread_limit(0);
  ASSERT_TRUE(first.ok() && second.ok());
  EXPECT_EQ(first->bone_count, default_bone_count(arm.rig.rest.V.rows()));
  EXPECT_EQ(first->key_points, second->key_points);
  EXPECT_EQ(first->check_points, second->check_points);
  EXPECT_TRUE(first->basis == second->basis);
  EXPECT_TRUE(first->mean == second->mean);
  EXPECT_EQ(first->epsilon.epsilon_min, second->epsilon.epsilon_min);
}

// The server reconstructs an articulated answer from each point's skinning terms (its kind's
// runtime, subspace.h), a client from the whole basis (coordinates.h): both are f̂ = mean + A p,
// here against that sum in double, alone and in a batch, within the bound pmsc_model.h states
// for any order of the float additions. And it estimates p through the same terms.
TEST(ArticulatedSubspace, TheSkinningTermsReconstructWhatTheWholeBasisDoes) {
  const ArmCase arm;
  auto model = train(arm.training, arm.options(SubspaceKind::kArticulated), nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  auto subspace = make_subspace(std::make_shared<const PmscModel>(*model));
  ASSERT_TRUE(subspace.ok()) << subspace.error().message;
  const Subspace& runtime = **subspace;
  std::vector<PoseEstimate> estimates(static_cast<size_t>(arm.new_shot.rows()));
  std::vector<const PoseEstimate*> inputs;
  Eigen::MatrixXf points(model->mean.size(), arm.new_shot.rows());
  std::vector<float*> destinations;
  for (long f = 0; f < arm.new_shot.rows(); ++f) {
    estimate_coordinates(*model, gather_key_values(*model, arm.new_shot.row(f).transpose()), estimates[f]);
    inputs.push_back(&estimates[f]);
    destinations.push_back(points.col(f).data());
  }
  const double u = reconstruction_rounding_bound(model->basis_size());
  const Eigen::MatrixXd A = model->basis.cast<double>();
  // Each kernel's path: the portable one takes the baseline skinning loop, BLAS the widest.
  const Kernel saved = active_kernel();
  for (Kernel kernel : {Kernel::kPortable, Kernel::kBlas}) {
    use_kernel(kernel);
    SCOPED_TRACE(kernel_name(kernel));
    runtime.reconstruct(inputs, destinations);  // one batch
    for (long f = 0; f < arm.new_shot.rows(); ++f) {
      const Eigen::VectorXd p = estimates[f].coordinates.cast<float>().cast<double>();
      const Eigen::VectorXd exact = model->mean.cast<double>() + A * p;
      const Eigen::VectorXd bound = u * (model->mean.cast<double>().cwiseAbs() + A.cwiseAbs() * p.cwiseAbs());
      Eigen::VectorXf alone(model->mean.size());
      float* destination = alone.data();
      const PoseEstimate* input = &estimates[f];
      runtime.reconstruct({&input, 1}, {&destination, 1});
      EXPECT_TRUE(((points.col(f).cast<double>() - exact).cwiseAbs().array() <= bound.array()).all())
          << "frame " << f << ": " << ((points.col(f).cast<double>() - exact).cwiseAbs() - bound).maxCoeff() << " over";
      EXPECT_TRUE(((alone.cast<double>() - exact).cwiseAbs().array() <= bound.array()).all()) << "frame " << f;
    }
  }
  use_kernel(saved);

  // Eq. 2 through the skinning terms (the runtime's estimate) against the dense projection P every
  // client and the reference use: the same p, errors and verdict inputs, within the precision the
  // normal equations keep at A_key's condition number (κ² · 2⁻⁵², relative).
  ASSERT_LE(model->condition_number, 1e4) << "the arm's keys take the runtime's own solve";
  const double precision = 1e4 * model->condition_number * model->condition_number * 0x1p-52;
  for (long f = 0; f < arm.new_shot.rows(); ++f) {
    const Eigen::VectorXf frame = arm.new_shot.row(f).transpose();
    Eigen::VectorXf checks(3 * model->check_point_count());
    for (int c = 0; c < model->check_point_count(); ++c) {
      checks.segment<3>(3 * c) = frame.segment<3>(3 * model->check_points[static_cast<size_t>(c)]);
    }
    PoseEstimate dense, served;
    estimate_coordinates(*model, gather_key_values(*model, frame), checks, dense);
    runtime.estimate(gather_key_values(*model, frame), checks, served);
    EXPECT_LE((served.coordinates - dense.coordinates).norm(), precision * dense.coordinates.norm()) << "frame " << f;
    EXPECT_NEAR(served.key_point_error, dense.key_point_error, precision * arm.diagonal) << "frame " << f;
    EXPECT_NEAR(served.key_point_max_error, dense.key_point_max_error, precision * arm.diagonal) << "frame " << f;
    EXPECT_NEAR(served.check_point_error, dense.check_point_error, precision * arm.diagonal) << "frame " << f;
    EXPECT_NEAR(served.error_estimate, dense.error_estimate, precision * arm.diagonal) << "frame " << f;
    EXPECT_EQ(served.checked, dense.checked);
  }

  // A basis whose bone columns are not of the skinning form is refused, naming the point.
  PmscModel corrupt = *model;
  corrupt.basis(3 * 5 + 1, 0) += 0.25f;  // point 5's y row in bone 0's x columns
  ASSERT_TRUE(prepare_projection(corrupt).ok());
  const auto refused = make_subspace(std::make_shared<const PmscModel>(std::move(corrupt)));
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(refused.error().message.find("point 5, bone 0"), std::string::npos) << refused.error().message;
}

// Issue #51: the rig an engine plays (articulated_rig.h). Its weights are the basis's, its bind
// pose the training rest pose (frame 0) plus the residual mean, and posed at an answer it differs
// from the model's f̂ = mean + A p exactly by the residual turned with the point's blended bone
// map, (Σ_j w_ij A_j − I)(μ_i + Σ_k p_k R_ik) — computed here from the basis's columns.
TEST(ArticulatedSubspace, TheRigPosesAnAnswerAsAnEngineDoes) {
  const ArmCase arm;
  auto model = train(arm.training, arm.options(SubspaceKind::kArticulated), nullptr);
  ASSERT_TRUE(model.ok()) << model.error().message;
  ASSERT_GT(model->residual_components, 0);
  const long N = model->point_count;
  const int B = model->bone_count;
  const long skinning = 12L * B;
  const Eigen::MatrixX3d rest =
      Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>>(arm.training.row(0).data(), N, 3)
          .cast<double>();
  auto rig = articulated_rig(*model, &rest);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const double tolerance = 1e-5 * arm.diagonal;
  const Eigen::MatrixXd A = model->basis.cast<double>();
  for (long i = 0; i < N; ++i) {
    // Weights: the basis's h_ij(3) where the term is not zero, summing to 1.
    double sum = 0;
    for (int32_t e = rig->offsets[static_cast<size_t>(i)]; e < rig->offsets[static_cast<size_t>(i) + 1]; ++e) {
      const int j = rig->bones[static_cast<size_t>(e)];
      EXPECT_NEAR(rig->weights[static_cast<size_t>(e)], A(3 * i, 12 * j + 3), 1e-6) << "point " << i;
      sum += rig->weights[static_cast<size_t>(e)];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12) << "point " << i;
    // The bind pose: frame 0 (the arm's bones share points: one set, placed on `rest`) plus μ.
    const Eigen::RowVector3d mean = model->mean.segment<3>(3 * i).cast<double>().transpose();
    EXPECT_LE((rig->bind_points.row(i) - mean - rest.row(i)).norm(), tolerance) << "point " << i;
  }
  for (long f = 0; f < arm.new_shot.rows(); f += 5) {
    PoseEstimate estimate;
    estimate_coordinates(*model, gather_key_values(*model, arm.new_shot.row(f).transpose()), estimate);
    const Eigen::VectorXd& p = estimate.coordinates;
    const Eigen::VectorXd exact = model->mean.cast<double>() + A * p;
    const Eigen::MatrixX3d posed = pose_rig(*model, *rig, p, estimate.alignment);
    double turned_most = 0;
    for (long i = 0; i < N; ++i) {
      Eigen::Matrix3d blended = Eigen::Matrix3d::Zero();
      for (int j = 0; j < B; ++j) {
        Eigen::Matrix3d linear;
        for (int r = 0; r < 3; ++r) linear.row(r) = p.segment<3>(12 * j + 4 * r).transpose();
        blended += A(3 * i, 12 * j + 3) * linear;
      }
      const Eigen::Vector3d residual =
          model->mean.segment<3>(3 * i).cast<double>() + A.block(3 * i, skinning, 3, model->residual_components) *
                                                             p.tail(model->residual_components);
      const Eigen::Vector3d expected = exact.segment<3>(3 * i) + (blended - Eigen::Matrix3d::Identity()) * residual;
      EXPECT_LE((posed.row(i).transpose() - expected).norm(), tolerance) << "frame " << f << ", point " << i;
      turned_most = std::max(turned_most, ((blended - Eigen::Matrix3d::Identity()) * residual).norm());
    }
    // The elbow at 80–120°: the turned residual is not nothing, so the check above has teeth.
    EXPECT_GT(turned_most, 100 * tolerance) << "frame " << f;
  }

  // Morph targets fitted to answers (the training frames'): the worst point over those answers,
  // measured here against f̂ in double, is the one reported and no worse than the plain rig's;
  // the ridge was chosen on the last 40%, where the fit is no worse than the plain rig either.
  std::vector<PoseEstimate> answers(static_cast<size_t>(arm.training.rows()));
  for (long f = 0; f < arm.training.rows(); ++f) {
    estimate_coordinates(*model, gather_key_values(*model, arm.training.row(f).transpose()),
                         answers[static_cast<size_t>(f)]);
  }
  RigFit fit;
  auto fitted = fit_articulated_rig(*model, &rest, answers, fit);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  double fitted_worst = 0, plain_worst = 0;
  for (const PoseEstimate& answer : answers) {
    const Eigen::VectorXd exact = model->mean.cast<double>() + A * answer.coordinates;
    const Eigen::MatrixX3d f_hat = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(exact.data(), N, 3);
    fitted_worst = std::max(fitted_worst, (pose_rig(*model, *fitted, answer.coordinates, answer.alignment) - f_hat).rowwise().norm().maxCoeff());
    plain_worst = std::max(plain_worst, (pose_rig(*model, *rig, answer.coordinates, answer.alignment) - f_hat).rowwise().norm().maxCoeff());
  }
  EXPECT_NEAR(fit.max_deviation, fitted_worst, 1e-9 * arm.diagonal);
  EXPECT_NEAR(fit.plain_max_deviation, plain_worst, 1e-9 * arm.diagonal);
  EXPECT_EQ(fit.held_out, arm.training.rows() - static_cast<long>(0.6 * arm.training.rows()));
  EXPECT_LE(fit.held_out_max_deviation, fit.held_out_plain_max_deviation);
  EXPECT_LT(fitted_worst, plain_worst) << "the arm's residual is a skinning weight error the fit can undo";
  // The skinning is untouched by the fit: same weights and centres.
  EXPECT_EQ(fitted->weights, rig->weights);
  EXPECT_EQ(fitted->centres, rig->centres);

  // The guarantee's tolerance as a share of the rest pose's diagonal (an articulated model's mean
  // is the residual's, no pose): here frame 0's, the rest the rig stands on.
  const double guaranteed = model->calibration.error_ratio * model->epsilon.epsilon_min;
  const double rest_diagonal = (rest.colwise().maxCoeff() - rest.colwise().minCoeff()).norm();
  char expected[160];
  std::snprintf(expected, sizeof expected, "(%.3g model units, %.3g%% of the rest pose's bounding-box diagonal)",
                guaranteed, 100 * guaranteed / rest_diagonal);
  PmscModel stated = *model;  // the arm's few folds state no guarantee; the sentence's scale is the point
  stated.calibration.bad_samples = 1000;
  EXPECT_NE(calibration_statement(stated).find(expected), std::string::npos) << calibration_statement(stated);

  // A linear model holds no rig.
  auto linear = train(arm.training, arm.options(SubspaceKind::kLinear), nullptr);
  ASSERT_TRUE(linear.ok()) << linear.error().message;
  const auto refused = articulated_rig(*linear);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(refused.error().message.find("articulated"), std::string::npos) << refused.error().message;
}

// "Train each night": misses of a new shot folded into an articulated model keep it articulated
// (its kind and counts from the stored options, its faces from mesh.faces), and the rest of the
// shot stays inside its tolerance.
TEST(ArticulatedSubspace, ARetrainKeepsTheKind) {
  const ArmCase arm;
  TrainingOptions options = arm.options(SubspaceKind::kArticulated);
  TrainingReport report;
  auto model = train(arm.training, options, &report);
  ASSERT_TRUE(model.ok()) << model.error().message;
  container::ModelContainer current = make_container(arm.rig.rest, arm.training, nullptr, *model, report, "arm");
  store_training_options(options, current);
  const FrameMatrix misses = arm.new_shot.topRows(20);
  auto retrained = retrain(current, 1, misses, 20, {}, "arm/1");
  ASSERT_TRUE(retrained.ok()) << retrained.error().message;
  auto loaded = load(retrained->container, "arm/2");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->subspace_kind, SubspaceKind::kArticulated);
  EXPECT_EQ(loaded->bone_count, 2);
  EXPECT_EQ(retrained->training_frames, arm.training.rows() + 20);
  // The rest of the new shot, which neither version trained on.
  EXPECT_LT(worst_point_error(*loaded, arm.new_shot.bottomRows(20)), 0.01 * arm.diagonal);
}

TEST(ArticulatedSubspace, OptionsItCannotHonourAreRefusedByName) {
  const ArmCase arm;
  const auto message = [&](TrainingOptions o, const FrameMatrix& frames) {
    auto model = train(frames, o, nullptr);
    return model.ok() ? std::string("trained") : model.error().message;
  };
  TrainingOptions o = arm.options(SubspaceKind::kArticulated);
  o.remove_rigid_motion = true;
  EXPECT_NE(message(o, arm.training).find("remove_rigid_motion"), std::string::npos);
  o = arm.options(SubspaceKind::kArticulated);
  o.bone_count = -1;
  EXPECT_NE(message(o, arm.training).find("bone_count"), std::string::npos);
  o = arm.options(SubspaceKind::kArticulated);
  o.residual_components = -2;
  EXPECT_NE(message(o, arm.training).find("residual_components"), std::string::npos);
  o = arm.options(SubspaceKind::kArticulated);
  o.bone_count = static_cast<int>(arm.rig.rest.V.rows()) + 1;
  EXPECT_NE(message(o, arm.training).find("bone_count"), std::string::npos);
  o = arm.options(SubspaceKind::kArticulated);
  o.channel_count = 1;
  EXPECT_NE(message(o, arm.training).find("3 channels"), std::string::npos);
}

}  // namespace
}  // namespace animspace::pmsc
