#include "core/animspace/skeleton_fit.h"

#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

using testing::random_bounded_rotation;
using testing::random_rotation;

Eigen::Matrix3Xd random_points(int count, std::mt19937_64& engine) {
  std::normal_distribution<double> normal;
  Eigen::Matrix3Xd points(3, count);
  for (int c = 0; c < count; ++c) points.col(c) = Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
  return points;
}

Eigen::Matrix3d rotation_of(const Transform& M) { return M.topLeftCorner<3, 3>(); }
Eigen::Vector3d translation_of(const Transform& M) { return M.topRightCorner<3, 1>(); }

Transform about_point(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& centre) {
  return make_transform(rotation, centre - rotation * centre);
}

TEST(SkeletonFitTest, RigidMotionIsRecoveredExactly) {
  std::mt19937_64 engine(1);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Matrix3d R = random_rotation(engine);
    const Eigen::Vector3d t = 3 * random_points(1, engine);
    const Eigen::Matrix3Xd rest = random_points(8, engine);
    bool reflection = true;
    const Transform M = fit_rigid_motion(rest, (R * rest).colwise() + t, &reflection);
    EXPECT_FALSE(reflection);
    EXPECT_TRUE(rotation_of(M).isApprox(R, 1e-12)) << trial;
    EXPECT_NEAR(rotation_of(M).determinant(), 1.0, 1e-12);
    EXPECT_TRUE(translation_of(M).isApprox(t, 1e-12)) << trial;
  }
}

// Coplanar core vertices leave the affine fit's normal column free; the polar factor is then a
// reflection about half the time, and the fix (negate S's smallest eigenvalue) must turn it into
// the true rotation.
TEST(SkeletonFitTest, CoplanarCoreVerticesGiveTheProperRotation) {
  std::mt19937_64 engine(2);
  const Eigen::Matrix3d plane = random_rotation(engine);
  Eigen::Matrix3Xd flat = random_points(12, engine);
  flat.row(2).setZero();
  const Eigen::Matrix3Xd rest = (plane * flat).colwise() + Eigen::Vector3d(1, 2, 3);
  ASSERT_TRUE(determines_rigid_motion(rest));
  int fixes = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Eigen::Matrix3d R = random_rotation(engine);
    const Eigen::Vector3d t = random_points(1, engine);
    bool reflection = false;
    const Transform M = fit_rigid_motion(rest, (R * rest).colwise() + t, &reflection);
    fixes += reflection ? 1 : 0;
    EXPECT_NEAR(rotation_of(M).determinant(), 1.0, 1e-12) << trial;
    EXPECT_TRUE(rotation_of(M).isApprox(R, 1e-9)) << trial;
    EXPECT_TRUE(translation_of(M).isApprox(t, 1e-9)) << trial;
  }
  EXPECT_GT(fixes, 0) << "no trial exercised the reflection fix";
}

TEST(SkeletonFitTest, TooFewOrCollinearPointsDoNotDetermineAMotion) {
  std::mt19937_64 engine(3);
  EXPECT_FALSE(determines_rigid_motion(random_points(2, engine)));
  Eigen::Matrix3Xd line(3, 5);
  for (int c = 0; c < 5; ++c) line.col(c) = Eigen::Vector3d(1, 2, 3) + c * Eigen::Vector3d(0.3, -0.1, 0.7);
  EXPECT_FALSE(determines_rigid_motion(line));
  EXPECT_TRUE(determines_rigid_motion(random_points(3, engine)));
}

// A chain root → 1 → 2 whose vertices each move rigidly with one bone, bone 1 rotating about
// `c1` in model space and bone 2 about `c2` relative to bone 1 (three-axis rotations, or a hinge
// about `hinge_axis` when it is non-zero). Everything scaled by `scale`.
struct Chain {
  PointMatrix reference;
  FrameMatrix meshes;
  Skeleton user;  // u_j = true joint + an offset
  std::vector<std::vector<int32_t>> core;
  std::vector<TransformList> motions;  // true M^p_j
  Eigen::Vector3d c1, c2;
};

Chain make_chain(double scale, const Eigen::Vector3d& hinge_axis, uint64_t seed) {
  std::mt19937_64 engine(seed);
  Chain chain;
  chain.c1 = scale * Eigen::Vector3d(0.2, -0.4, 0.5);
  chain.c2 = scale * Eigen::Vector3d(1.1, 0.3, 0.2);
  const int per_bone = 25, examples = 10;
  Eigen::Matrix3Xd points(3, 2 * per_bone);
  std::uniform_real_distribution<double> along(0.1, 0.9);
  std::normal_distribution<double> normal(0, 0.2);
  for (int c = 0; c < 2 * per_bone; ++c) {
    const Eigen::Vector3d from = c < per_bone ? chain.c1 : chain.c2;
    const Eigen::Vector3d to = c < per_bone ? chain.c2 : Eigen::Vector3d(chain.c2 + scale * Eigen::Vector3d(0.8, 0.5, -0.3));
    points.col(c) = from + along(engine) * (to - from) + scale * Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
  }
  chain.reference = points.transpose().cast<float>();
  chain.core = {{}, {}, {}};
  for (int c = 0; c < 2 * per_bone; ++c) chain.core[c < per_bone ? 1 : 2].push_back(c);
  chain.user.parents = {-1, 0, 1};
  const Eigen::Vector3d offset = scale * Eigen::Vector3d(0.3, -0.2, 0.1);
  chain.user.rest = {Transform::Identity(), make_transform(Eigen::Matrix3d::Identity(), chain.c1 + offset),
                     make_transform(Eigen::Matrix3d::Identity(), chain.c2 + offset)};
  chain.meshes.resize(examples, 3L * points.cols());
  std::uniform_real_distribution<double> angle(-1.2, 1.2);
  for (int p = 0; p < examples; ++p) {
    const Transform M1 = about_point(random_bounded_rotation(engine, 1.2), chain.c1);
    const Eigen::Matrix3d R2 = hinge_axis.isZero() ? Eigen::Matrix3d(random_bounded_rotation(engine, 1.2))
                                                   : Eigen::Matrix3d(Eigen::AngleAxisd(angle(engine), hinge_axis.normalized()));
    const Transform M2 = M1 * about_point(R2, chain.c2);
    chain.motions.push_back({Transform::Identity(), M1, M2});
    for (int c = 0; c < points.cols(); ++c) {
      const Eigen::Vector3d v = ((c < per_bone ? M1 : M2) * points.col(c).homogeneous()).head<3>();
      for (int a = 0; a < 3; ++a) chain.meshes(p, 3L * c + a) = static_cast<float>(v(a));
    }
  }
  return chain;
}

TEST(SkeletonFitTest, RecoversRigidBoneMotionsAndConsistentPoses) {
  const Chain chain = make_chain(1.0, Eigen::Vector3d::Zero(), 4);
  SkeletonFitReport report;
  const auto fitted = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core, {}, &report);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  ASSERT_TRUE(validate(fitted->skeleton).ok());
  ASSERT_EQ(fitted->poses.size(), chain.motions.size());
  for (size_t p = 0; p < chain.motions.size(); ++p) {
    EXPECT_TRUE(fitted->poses[p][0].isIdentity(0));
    for (size_t j = 1; j < 3; ++j) {
      const Transform& M = fitted->motions[p][j];
      EXPECT_NEAR(rotation_of(M).determinant(), 1.0, 1e-12);
      // Float data: agreement to ~1e-6.
      EXPECT_LT((M - chain.motions[p][j]).cwiseAbs().maxCoeff(), 1e-5) << "example " << p << " bone " << j;
      // G^p_j = M^p_j Ĝ_j with Ĝ_j a pure translation.
      EXPECT_TRUE(rotation_of(fitted->skeleton.rest[j]).isIdentity(0));
      EXPECT_LT((fitted->poses[p][j] - M * fitted->skeleton.rest[j]).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  EXPECT_LT(report.rigid_rms[1], 1e-5);
  EXPECT_LT(report.rigid_rms[2], 1e-5);
}

// Joints that rotate about a point in three axes: the translation variance can be made zero only
// at the true centre, which eq. 4.6 must find whatever the user's guess and whatever the scale.
TEST(SkeletonFitTest, JointPlacementFindsTheRotationCentreAtAnyScale) {
  for (const double scale : {1e-4, 1.0, 1e4}) {
    const Chain chain = make_chain(scale, Eigen::Vector3d::Zero(), 5);
    SkeletonFitReport report;
    const auto fitted = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core, {}, &report);
    ASSERT_TRUE(fitted.ok()) << fitted.error().message;
    const Eigen::Vector3d h1 = translation_of(fitted->skeleton.rest[1]);
    const Eigen::Vector3d h2 = translation_of(fitted->skeleton.rest[2]);
    EXPECT_LT((h1 - chain.c1).norm(), 1e-5 * scale) << scale;
    EXPECT_LT((h2 - chain.c2).norm(), 1e-5 * scale) << scale;
    EXPECT_LT(report.joint_spread[1], 1e-5 * scale) << scale;
    EXPECT_LT(report.joint_spread[2], 1e-5 * scale) << scale;
    // With the joints at the rotation centres the joint transforms are pure rotations (L̲ fixed).
    const TransformList L0 = joint_transforms(fitted->skeleton, fitted->poses[0]);
    for (size_t p = 1; p < fitted->poses.size(); ++p) {
      const TransformList L = joint_transforms(fitted->skeleton, fitted->poses[p]);
      EXPECT_LT((translation_of(L[2]) - translation_of(L0[2])).norm(), 1e-5 * scale);
    }
  }
}

// A hinge leaves the joint anywhere on its axis; λ (h − u) = 0 keeps it at the point of the axis
// nearest the user's guess u.
TEST(SkeletonFitTest, HingeJointStaysNearUserGuessAlongTheAxis) {
  const Eigen::Vector3d axis = Eigen::Vector3d(0.3, 1.0, -0.5).normalized();
  const Chain chain = make_chain(1.0, axis, 6);
  const auto fitted = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  const Eigen::Vector3d u = translation_of(chain.user.rest[2]);
  const Eigen::Vector3d expected = chain.c2 + (u - chain.c2).dot(axis) * axis;
  EXPECT_LT((translation_of(fitted->skeleton.rest[2]) - expected).norm(), 1e-4);
  // The three-axis joint is still found exactly.
  EXPECT_LT((translation_of(fitted->skeleton.rest[1]) - chain.c1).norm(), 1e-5);

  SkeletonFitOptions options;
  options.joint_regularisation = 0;
  const auto undetermined = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core, options);
  ASSERT_FALSE(undetermined.ok());
  EXPECT_EQ(undetermined.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(undetermined.error().message.find("bone 2"), std::string::npos) << undetermined.error().message;
}

TEST(SkeletonFitTest, UndeterminedBoneIsAnErrorOrInheritsItsParent) {
  Chain chain = make_chain(1.0, Eigen::Vector3d::Zero(), 7);
  chain.core[2].resize(2);
  const auto rejected = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core);
  ASSERT_FALSE(rejected.ok());
  EXPECT_EQ(rejected.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(rejected.error().message.find("bone 2"), std::string::npos) << rejected.error().message;

  SkeletonFitOptions options;
  options.inherit_undetermined_bones = true;
  SkeletonFitReport report;
  const auto fitted = fit_skeleton(chain.reference, chain.meshes, chain.user, chain.core, options, &report);
  ASSERT_TRUE(fitted.ok()) << fitted.error().message;
  EXPECT_EQ(report.inherited_bones, std::vector<int32_t>{2});
  for (const TransformList& M : fitted->motions) EXPECT_EQ(M[2], M[1]);
  // Moving rigidly with its parent, the joint's translation does not vary: it stays at u.
  EXPECT_LT((translation_of(fitted->skeleton.rest[2]) - translation_of(chain.user.rest[2])).norm(), 1e-9);
}

TEST(SkeletonFitTest, RejectsMalformedInputNamingIt) {
  const Chain chain = make_chain(1.0, Eigen::Vector3d::Zero(), 8);
  auto core = chain.core;
  core[0] = {0, 1, 2};
  auto result = fit_skeleton(chain.reference, chain.meshes, chain.user, core);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("bone 0"), std::string::npos) << result.error().message;

  core = chain.core;
  core[1].push_back(static_cast<int32_t>(chain.reference.rows()));
  result = fit_skeleton(chain.reference, chain.meshes, chain.user, core);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("bone 1"), std::string::npos) << result.error().message;

  FrameMatrix meshes = chain.meshes;
  meshes.conservativeResize(meshes.rows(), meshes.cols() - 3);
  result = fit_skeleton(chain.reference, meshes, chain.user, chain.core);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace animspace::animation_space
