// Skinning decomposition (SSDR): the simplex QP against brute force, the bone-motion Procrustes
// against an SVD reference, pose solving and the whole alternation against generated sequences
// whose skinning is known.
#include "core/animspace/skinning_decomposition.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "core/animspace/bone_motions.h"
#include "core/animspace/fit_sequence.h"
#include "core/animspace/segmentation.h"
#include "core/animspace/skeleton_fit.h"
#include "core/geometry/rigid_fit.h"
#include "tests/support/animspace_fixtures.h"
#include "tests/support/articulated_tube.h"

namespace animspace::animation_space {
namespace {

using testing::make_tube;

double objective(const Eigen::MatrixXd& Q, const Eigen::VectorXd& c, const Eigen::VectorXd& w) {
  return 0.5 * w.dot(Q * w) - c.dot(w);
}

// Every support S: the equality-constrained minimiser on S (KKT, least-squares solve), kept when
// it is non-negative; the best over all supports is the simplex minimum.
Eigen::VectorXd brute_force_simplex_qp(const Eigen::MatrixXd& Q, const Eigen::VectorXd& c) {
  const int n = static_cast<int>(c.size());
  Eigen::VectorXd best;
  double best_value = std::numeric_limits<double>::infinity();
  for (int mask = 1; mask < (1 << n); ++mask) {
    std::vector<int> support;
    for (int j = 0; j < n; ++j) {
      if (mask & (1 << j)) support.push_back(j);
    }
    const int m = static_cast<int>(support.size());
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(m + 1, m + 1);
    Eigen::VectorXd rhs(m + 1);
    for (int a = 0; a < m; ++a) {
      for (int b = 0; b < m; ++b) K(a, b) = Q(support[static_cast<size_t>(a)], support[static_cast<size_t>(b)]);
      K(a, m) = K(m, a) = 1;
      rhs(a) = c(support[static_cast<size_t>(a)]);
    }
    rhs(m) = 1;
    const Eigen::VectorXd z = K.fullPivLu().solve(rhs);
    if ((K * z - rhs).norm() > 1e-9 * (1 + rhs.norm())) continue;
    if ((z.head(m).array() < -1e-12).any()) continue;
    Eigen::VectorXd w = Eigen::VectorXd::Zero(n);
    for (int a = 0; a < m; ++a) w(support[static_cast<size_t>(a)]) = z(a);
    const double value = objective(Q, c, w);
    if (value < best_value) {
      best_value = value;
      best = w;
    }
  }
  return best;
}

TEST(SimplexQpTest, MatchesBruteForceOnRandomProblems) {
  std::mt19937_64 engine(7);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 1 + trial % 6;
    // Q = AᵀA from a tall A (a skinning problem's shape), sometimes rank-deficient.
    const int rows = trial % 5 == 0 ? std::max(1, n - 2) : 3 * n;
    Eigen::MatrixXd A(rows, n);
    for (int r = 0; r < rows; ++r) {
      for (int j = 0; j < n; ++j) A(r, j) = normal(engine);
    }
    Eigen::VectorXd b(rows);
    for (int r = 0; r < rows; ++r) b(r) = normal(engine);
    const Eigen::MatrixXd Q = A.transpose() * A;
    const Eigen::VectorXd c = A.transpose() * b;
    const Eigen::VectorXd w = solve_simplex_qp(Q, c);
    ASSERT_EQ(w.size(), n);
    EXPECT_GE(w.minCoeff(), 0.0) << "trial " << trial;
    EXPECT_NEAR(w.sum(), 1.0, 1e-12) << "trial " << trial;
    const Eigen::VectorXd reference = brute_force_simplex_qp(Q, c);
    EXPECT_LE(objective(Q, c, w), objective(Q, c, reference) + 1e-9 * (1 + std::abs(objective(Q, c, reference))))
        << "trial " << trial;
  }
}

TEST(SimplexQpTest, HandWorkedCases) {
  // One variable: the only point of the simplex.
  EXPECT_DOUBLE_EQ(solve_simplex_qp(Eigen::MatrixXd::Constant(1, 1, 3.0), Eigen::VectorXd::Constant(1, -5.0))(0), 1.0);
  // ½‖w − t‖² with t inside the simplex: w = t.
  const Eigen::Vector3d t(0.2, 0.5, 0.3);
  EXPECT_LT((solve_simplex_qp(Eigen::Matrix3d::Identity(), t) - t).norm(), 1e-12);
  // t outside: the Euclidean projection onto the simplex, (1.5, −1, 0.5) → (1, 0, 0) (shift by
  // 0.5, clip: 1.0, 0, 0.0).
  const Eigen::VectorXd w = solve_simplex_qp(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1.5, -1.0, 0.5));
  EXPECT_LT((w - Eigen::Vector3d(1.0, 0.0, 0.0)).norm(), 1e-12);
  // Two identical bones (singular Q): any split is optimal; the result is still on the simplex.
  Eigen::Matrix2d Q;
  Q << 1, 1, 1, 1;
  const Eigen::VectorXd split = solve_simplex_qp(Q, Eigen::Vector2d(1, 1));
  EXPECT_NEAR(split.sum(), 1.0, 1e-12);
  EXPECT_GE(split.minCoeff(), 0.0);
}

TEST(BoneMotionTest, LinearBlendCaseMatchesWeightedKabsch) {
  // x_i = w_i p_i: SSDR's weighted Procrustes, i.e. Kabsch with weights w_i² from p_i to q_i / w_i.
  std::mt19937_64 engine(11);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> weight(0.05, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const int n = 5 + trial;
    Eigen::Matrix3Xd p(3, n), x(3, n), q(3, n);
    Eigen::VectorXd w(n);
    for (int i = 0; i < n; ++i) {
      p.col(i) = Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
      w(i) = weight(engine);
      x.col(i) = w(i) * p.col(i);
      q.col(i) = Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    }
    const Transform M = fit_bone_motion(x, w, q);
    Eigen::Matrix3Xd targets = q;
    for (int i = 0; i < n; ++i) targets.col(i) /= w(i);
    const geometry::RigidTransform reference = geometry::fit_rigid(p, targets, w.cwiseAbs2());
    EXPECT_LT((M.topLeftCorner<3, 3>() - reference.rotation).norm(), 1e-9) << "trial " << trial;
    EXPECT_LT((M.topRightCorner<3, 1>() - reference.translation).norm(), 1e-9) << "trial " << trial;
    const double determinant = M.topLeftCorner<3, 3>().determinant();
    EXPECT_NEAR(determinant, 1.0, 1e-12);
  }
}

TEST(BoneMotionTest, RecoversAKnownMotionForGeneralInfluenceVectors) {
  // Animation-space influences (x, w) with weights of either sign, exact data q = R x + w t.
  std::mt19937_64 engine(12);
  std::normal_distribution<double> normal;
  const Eigen::Matrix3d R = testing::random_rotation(engine);
  const Eigen::Vector3d t(0.3, -2.0, 1.5);
  const int n = 12;
  Eigen::Matrix3Xd x(3, n), q(3, n);
  Eigen::VectorXd w(n);
  for (int i = 0; i < n; ++i) {
    x.col(i) = Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    w(i) = normal(engine);
    q.col(i) = R * x.col(i) + w(i) * t;
  }
  const Transform M = fit_bone_motion(x, w, q);
  EXPECT_LT((M.topLeftCorner<3, 3>() - R).norm(), 1e-10);
  EXPECT_LT((M.topRightCorner<3, 1>() - t).norm(), 1e-10);
  // And it is a minimum: no nearby rigid motion does better on noisy data.
  for (int i = 0; i < n; ++i) q.col(i) += 0.1 * Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
  const Transform best = fit_bone_motion(x, w, q);
  const auto energy = [&](const Transform& T) {
    return ((T.topLeftCorner<3, 3>() * x + T.topRightCorner<3, 1>() * w.transpose()) - q).squaredNorm();
  };
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Matrix3d turn = testing::random_bounded_rotation(engine, 0.05);
    const Transform nearby = make_transform(turn * best.topLeftCorner<3, 3>(),
                                            best.topRightCorner<3, 1>() + 0.01 * Eigen::Vector3d::Random());
    EXPECT_GE(energy(nearby), energy(best) - 1e-12);
  }
}

// A linear blend tube model (the generator's weights as influences, bone s + 1 for segment s).
LinearBlendModel tube_model(const testing::ArticulatedTube& tube) {
  LinearBlendModel model;
  const int segments = static_cast<int>(tube.weights.cols());
  model.skeleton.parents.push_back(-1);
  model.skeleton.rest.push_back(Transform::Identity());
  for (int s = 0; s < segments; ++s) {
    model.skeleton.parents.push_back(s);
    model.skeleton.rest.push_back(make_transform(Eigen::Matrix3d::Identity(), tube.joint[static_cast<size_t>(s)]));
  }
  model.faces = tube.faces;
  model.rest_points = tube.rest.transpose().cast<double>();
  std::vector<double> weights;
  for (Eigen::Index i = 0; i < tube.rest.rows(); ++i) {
    for (int s = 0; s < segments; ++s) {
      if (tube.weights(i, s) == 0) continue;
      model.influences.bones.push_back(s + 1);
      weights.push_back(tube.weights(i, s));
    }
    model.influences.offsets.push_back(static_cast<int32_t>(model.influences.bones.size()));
  }
  model.weights = Eigen::Map<Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  return model;
}

TEST(BoneMotionTest, SolvePoseRecoversTheMotionsOfAKnownRig) {
  const auto tube = make_tube(3, 6, 4, 31, 2.0);
  const LinearBlendModel model = tube_model(tube);
  PointMatrix posed;
  for (Eigen::Index f = 0; f < tube.frames.rows(); ++f) {
    const TransformList globals = solve_pose(model, tube.frames.row(f));
    evaluate(model, globals, posed);
    const Eigen::Map<const PointMatrix> captured(tube.frames.row(f).data(), posed.rows(), 3);
    EXPECT_LT((posed - captured).cwiseAbs().maxCoeff(), 1e-5) << "frame " << f;
    // The motions themselves: M_j = G_j Ĝ_j⁻¹ is the generator's segment motion.
    for (int s = 0; s < 3; ++s) {
      const Transform M = globals[static_cast<size_t>(s) + 1] * affine_inverse(model.skeleton.rest[static_cast<size_t>(s) + 1]);
      EXPECT_LT((M - tube.motions[static_cast<size_t>(f)][static_cast<size_t>(s)]).cwiseAbs().maxCoeff(), 1e-5)
          << "frame " << f << " segment " << s;
    }
  }
}

TEST(BoneMotionTest, RefiningMotionsNeverRaisesTheError) {
  const auto tube = make_tube(4, 5, 3, 32, 2.0);
  const LinearBlendModel model = tube_model(tube);
  const MotionSkinning skinning = motion_skinning(model);
  const BoneInfluences by_bone = bone_influences(skinning.influences, model.skeleton.bone_count());
  std::mt19937_64 engine(3);
  TransformList motions(5, Transform::Identity());
  for (size_t j = 1; j < motions.size(); ++j) {
    motions[j] = make_transform(testing::random_bounded_rotation(engine, 1.0), Eigen::Vector3d::Random());
  }
  const Eigen::Matrix3Xd frame = frame_points(tube.frames.row(1));
  double previous = std::numeric_limits<double>::infinity();
  for (int sweep = 0; sweep < 20; ++sweep) {
    const double error = refine_motions(skinning, by_bone, frame, motions, 1);
    EXPECT_LE(error, previous * (1 + 1e-12) + 1e-18) << "sweep " << sweep;
    previous = error;
  }
}

TEST(SkinningDecompositionTest, RecoversASmoothlySkinnedTube) {
  const int segments = 4;
  const auto tube = make_tube(segments, 8, 24, 41, 3.0);
  SegmentationOptions segmentation_options;
  segmentation_options.bone_count = segments;
  auto segmentation = segment_rigid_parts(tube.rest, tube.faces, tube.frames, segmentation_options);
  ASSERT_TRUE(segmentation) << segmentation.error().message;
  DecompositionOptions options;
  options.weights.max_influences = 2;
  DecompositionReport report;
  int progress_calls = 0;
  auto result = decompose_skinning(tube.rest, tube.faces, tube.frames, segmentation->labels, segmentation->transforms,
                                   options, &report, [&](std::string_view, int64_t, int64_t) { ++progress_calls; });
  ASSERT_TRUE(result) << result.error().message;
  const double length = segments * 8 * testing::ArticulatedTube::kRingSpacing;
  // Rigid parts cannot follow the blended joints; the decomposition can, almost exactly.
  EXPECT_GT(report.initial_rms, 1e-3 * length);
  EXPECT_LT(result->rms, 0.05 * report.initial_rms);
  EXPECT_LT(result->rms, 2e-4 * length);
  EXPECT_GT(progress_calls, 1);
  // The result is the best iterate, and the first iterations (far from convergence) each lower
  // the error.
  double best = report.initial_rms;
  for (const auto& iteration : report.iterations) best = std::min(best, iteration.rms);
  EXPECT_DOUBLE_EQ(result->rms, best);
  ASSERT_GE(report.iterations.size(), 2u);
  EXPECT_LT(report.iterations[0].rms, report.initial_rms);
  EXPECT_LT(report.iterations[1].rms, report.iterations[0].rms);
  // Weights: on the simplex, at most K per vertex, never on the root.
  const SkinningWeights& w = result->weights;
  for (int i = 0; i < w.influences.vertex_count(); ++i) {
    double sum = 0;
    EXPECT_LE(w.influences.end(i) - w.influences.begin(i), 2);
    for (int k = w.influences.begin(i); k < w.influences.end(i); ++k) {
      EXPECT_GE(w.weights(k), 0.0);
      EXPECT_NE(w.influences.bones[static_cast<size_t>(k)], 0);
      sum += w.weights(k);
    }
    EXPECT_NEAR(sum, 1.0, 1e-9);
  }
  // The motions are rigid, and bone 0 is the identity.
  for (const TransformList& frame : result->motions) {
    EXPECT_TRUE(frame[0].isIdentity(0));
    for (const Transform& M : frame) {
      EXPECT_LT((M.topLeftCorner<3, 3>().transpose() * M.topLeftCorner<3, 3>() - Eigen::Matrix3d::Identity()).norm(), 1e-9);
    }
  }
}

TEST(SkinningDecompositionTest, HeldOutFramesOfTheSameRigAreReproduced) {
  // Fit on the even frames of a blended tube, solve the odd frames' motions with the weights
  // fixed: the rig generalises because it is the generator's.
  const auto tube = make_tube(3, 8, 30, 42, 3.0);
  FrameMatrix train((tube.frames.rows() + 1) / 2, tube.frames.cols()), test(tube.frames.rows() / 2, tube.frames.cols());
  for (Eigen::Index f = 0; f < tube.frames.rows(); ++f) (f % 2 == 0 ? train : test).row(f / 2) = tube.frames.row(f);
  TriangleMesh reference;
  reference.V = tube.rest;
  reference.F = tube.faces;
  SequenceFitOptions options;
  options.segmentation.bone_count = 3;
  auto skeleton = fit_sequence_skeleton(reference, train, options, nullptr);
  ASSERT_TRUE(skeleton) << skeleton.error().message;
  auto lbs = fit_sequence_linear_blend(reference, train, *skeleton, options.fit, nullptr);
  ASSERT_TRUE(lbs) << lbs.error().message;
  ASSERT_TRUE(validate(*lbs).ok());
  std::vector<TransformList> poses;
  for (Eigen::Index f = 0; f < test.rows(); ++f) poses.push_back(solve_pose(*lbs, test.row(f)));
  const double length = 3 * 8 * testing::ArticulatedTube::kRingSpacing;
  EXPECT_LT(reconstruction_error(*lbs, poses, test).rms, 5e-4 * length);
  // The first pass on the same frames is the baseline the decomposition must beat.
  options.decompose = false;
  auto first_skeleton = fit_sequence_skeleton(reference, train, options, nullptr);
  ASSERT_TRUE(first_skeleton);
  auto first = fit_sequence_linear_blend(reference, train, *first_skeleton, options.fit, nullptr);
  ASSERT_TRUE(first);
  EXPECT_LT(reconstruction_error(*lbs, skeleton->training_poses, train).rms,
            reconstruction_error(*first, first_skeleton->training_poses, train).rms);
}

TEST(SkinningDecompositionTest, AnimationSpaceRefinementLowersTheErrorOfAKnownModel) {
  // Animation space holds every linear blend model (§3.1), so its refit on the decomposition's
  // poses is at least as close, and each refinement round (motions, then model) must not raise
  // the error (δ = 0 and λ = 1e-12: the objective is the error; the default λ = 1e-6 outweighs
  // errors as small as these).
  const auto tube = make_tube(3, 8, 20, 43, 3.0);
  TriangleMesh reference;
  reference.V = tube.rest;
  reference.F = tube.faces;
  SequenceFitOptions options;
  options.segmentation.bone_count = 3;
  options.fit.edge_regularisation = 0;
  options.fit.vertex_regularisation = 1e-12;
  auto sequence_skeleton = fit_sequence_skeleton(reference, tube.frames, options, nullptr);
  ASSERT_TRUE(sequence_skeleton);
  auto lbs = fit_sequence_linear_blend(reference, tube.frames, *sequence_skeleton, options.fit, nullptr);
  auto as = fit_sequence_model(reference, tube.frames, *sequence_skeleton, options.fit, nullptr);
  ASSERT_TRUE(lbs && as);
  std::vector<TransformList> poses = sequence_skeleton->training_poses;
  double previous = reconstruction_error(*as, poses, tube.frames).rms;
  EXPECT_LE(previous, reconstruction_error(*lbs, sequence_skeleton->training_poses, tube.frames).rms * (1 + 1e-6));
  for (int round = 0; round < 3; ++round) {
    auto refined = refine_animation_space(tube.frames, *as, poses, options.fit, 1);
    ASSERT_TRUE(refined);
    const double error = reconstruction_error(*refined, poses, tube.frames).rms;
    EXPECT_LE(error, previous * (1 + 1e-6) + 1e-12) << "round " << round;
    previous = error;
    as = std::move(refined);
  }
}

TEST(SkinningDecompositionTest, RecoversAKnownAnimationSpaceModel) {
  // Frames of a genuine animation-space model: the blended tube's linear blend skinning plus, on
  // every blended vertex, an offset d on one bone's 4-vector and −d on the other's (weight 0, so the
  // rest pose is unchanged while posed frames get R_a d − R_b d, which no linear blend weights give).
  const auto tube = make_tube(3, 8, 24, 45, 3.0);
  const double length = 3 * 8 * testing::ArticulatedTube::kRingSpacing;
  std::mt19937_64 engine(46);
  std::normal_distribution<double> normal;
  FrameMatrix frames = tube.frames;
  for (Eigen::Index i = 0; i < tube.rest.rows(); ++i) {
    std::vector<int> bones;
    for (int s = 0; s < 3; ++s) {
      if (tube.weights(i, s) != 0) bones.push_back(s);
    }
    if (bones.size() != 2) continue;
    const Eigen::Vector3d d = 0.003 * length * Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    for (Eigen::Index f = 0; f < frames.rows(); ++f) {
      const auto& M = tube.motions[static_cast<size_t>(f)];
      const Eigen::Vector3d extra = M[static_cast<size_t>(bones[0])].topLeftCorner<3, 3>() * d -
                                    M[static_cast<size_t>(bones[1])].topLeftCorner<3, 3>() * d;
      frames.block<1, 3>(f, 3 * i) += extra.cast<float>().transpose();
    }
  }
  TriangleMesh reference;
  reference.V = tube.rest;
  reference.F = tube.faces;
  SequenceFitOptions options;
  options.segmentation.bone_count = 3;
  options.fit.edge_regularisation = 0;
  options.fit.vertex_regularisation = 1e-12;
  std::vector<TransformList> poses;
  auto model = fit_sequence(reference, frames, options, nullptr, &poses);
  ASSERT_TRUE(model) << model.error().message;
  auto skeleton = fit_sequence_skeleton(reference, frames, options, nullptr);
  ASSERT_TRUE(skeleton) << skeleton.error().message;
  auto lbs = fit_sequence_linear_blend(reference, frames, *skeleton, options.fit, nullptr);
  ASSERT_TRUE(lbs);
  const double as_error = reconstruction_error(*model, poses, frames).rms;
  const double lbs_error = reconstruction_error(*lbs, skeleton->training_poses, frames).rms;
  // The offsets move blended vertices by ~0.5% of the length; linear blend skinning cannot follow
  // them, animation space on the same influence sets can (to within the motions, which start from
  // the linear blend fit and each refinement round brings closer).
  EXPECT_GT(lbs_error, 5e-4 * length);
  EXPECT_LT(as_error, 0.1 * lbs_error);
  EXPECT_LT(as_error, 1e-4 * length);
}

TEST(SkinningDecompositionTest, InvalidInputIsRejectedWithAPreciseMessage) {
  const auto tube = make_tube(2, 4, 3, 44);
  std::vector<int32_t> labels(static_cast<size_t>(tube.rest.rows()), 1);
  std::vector<TransformList> motions(3, TransformList(3, Transform::Identity()));
  const auto message = [&](const PointMatrix& rest, const FrameMatrix& frames, const std::vector<int32_t>& l,
                           const std::vector<TransformList>& m, const DecompositionOptions& o) {
    auto result = decompose_skinning(rest, tube.faces, frames, l, m, o);
    EXPECT_FALSE(result);
    if (result) return std::string();
    EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument);
    return result.error().message;
  };
  const DecompositionOptions ok;
  EXPECT_NE(message(tube.rest, tube.frames.leftCols(6), labels, motions, ok).find("frames"), std::string::npos);
  std::vector<int32_t> bad_labels = labels;
  bad_labels[5] = 3;
  EXPECT_NE(message(tube.rest, tube.frames, bad_labels, motions, ok).find("labels[5]"), std::string::npos);
  EXPECT_NE(message(tube.rest, tube.frames, labels, std::vector<TransformList>(2, motions[0]), ok).find("initial_motions"),
            std::string::npos);
  DecompositionOptions bad = ok;
  bad.weights.max_influences = 0;
  EXPECT_NE(message(tube.rest, tube.frames, labels, motions, bad).find("max_influences"), std::string::npos);
  FrameMatrix nan = tube.frames;
  nan(1, 4) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(message(tube.rest, nan, labels, motions, ok).find("non-finite"), std::string::npos);
}

TEST(SkeletonFromMotionsTest, PlacesAHingeJointOnItsAxis) {
  // Two bones: bone 1 fixed, bone 2 turning about a known axis through a known point c in every
  // example. Eq. 4.6 puts the joint where the translation varies least: on the axis; λ picks the
  // point of the axis nearest u.
  const Eigen::Vector3d c(1.0, 2.0, -0.5), axis = Eigen::Vector3d(0.2, 1.0, 0.3).normalized();
  std::vector<TransformList> motions;
  for (int k = 0; k < 6; ++k) {
    const Eigen::Affine3d turn =
        Eigen::Translation3d(c) * Eigen::AngleAxisd(0.3 * k - 0.7, axis) * Eigen::Translation3d(-c);
    motions.push_back(TransformList{Transform::Identity(), Transform::Identity(), turn.matrix()});
  }
  Skeleton user;
  user.parents = {-1, 0, 1};
  const Eigen::Vector3d u(1.5, 2.5, 0.0);
  user.rest = {Transform::Identity(), Transform::Identity(), make_transform(Eigen::Matrix3d::Identity(), u)};
  auto skeleton = skeleton_from_motions(user, motions, 1e-3);
  ASSERT_TRUE(skeleton) << skeleton.error().message;
  const Eigen::Vector3d h = skeleton->rest[2].topRightCorner<3, 1>();
  const Eigen::Vector3d expected = c + axis * axis.dot(u - c);
  EXPECT_LT((h - expected).norm(), 1e-3);
}

}  // namespace
}  // namespace animspace::animation_space
