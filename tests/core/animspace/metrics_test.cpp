// Tests of the animation-space metrics (Merry 2007 §3.3, §3.4, §7.2).
//
// Reference values are computed independently of the code under test: Monte Carlo over poses
// drawn here from the same joint models (with a standard error computed in the test), closed forms
// worked out by hand, numeric quadrature, and recomputation from transformed inputs.
#include "core/animspace/metrics.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "tests/support/animspace_fixtures.h"

namespace animspace::animation_space {
namespace {

using testing::random_model;
using testing::random_rotation;
using testing::random_skeleton;

constexpr double kPi = 3.14159265358979323846;

// --- Independent samplers -------------------------------------------------------------------

// One draw of L_j from `distribution` about the rest joint transform `rest`.
Transform sample_joint(const JointDistribution& distribution, const Transform& rest, std::mt19937_64& engine) {
  Transform L = rest;
  switch (distribution.kind) {
    case JointModel::kFixed:
      break;
    case JointModel::kAxisRange: {
      const double phi = std::uniform_real_distribution<double>(distribution.angle_min, distribution.angle_max)(engine);
      L.topLeftCorner<3, 3>() = rest.topLeftCorner<3, 3>() * Eigen::AngleAxisd(phi, distribution.axis).toRotationMatrix();
      break;
    }
    case JointModel::kUniformRotation:
      L.topLeftCorner<3, 3>() = rest.topLeftCorner<3, 3>() * random_rotation(engine);
      break;
    case JointModel::kSampled: {
      const size_t n = std::uniform_int_distribution<size_t>(0, distribution.samples.size() - 1)(engine);
      L = distribution.samples[n];
      break;
    }
  }
  return L;
}

TransformList sample_pose(const Skeleton& skeleton, const std::vector<JointDistribution>& distributions,
                          std::mt19937_64& engine) {
  const TransformList rest = rest_joint_transforms(skeleton);
  TransformList joints(rest.size());
  for (size_t j = 0; j < rest.size(); ++j) joints[j] = sample_joint(distributions[j], rest[j], engine);
  return global_transforms(skeleton, joints);
}

// The animation matrix G = (G_0 … G_{b-1}) of eq. 3.2.
Eigen::MatrixXd animation_matrix(const TransformList& globals) {
  Eigen::MatrixXd G(4, 4 * static_cast<Eigen::Index>(globals.size()));
  for (size_t j = 0; j < globals.size(); ++j) G.middleCols<4>(4 * static_cast<Eigen::Index>(j)) = globals[j];
  return G;
}

// A random dense animation-space vector of weight 0.
Eigen::VectorXd random_vector(int bones, std::mt19937_64& engine) {
  std::normal_distribution<double> normal;
  Eigen::VectorXd s(4 * bones);
  for (Eigen::Index k = 0; k < s.size(); ++k) s(k) = normal(engine);
  double weight = 0;
  for (int j = 0; j < bones; ++j) weight += s(4 * j + 3);
  for (int j = 0; j < bones; ++j) s(4 * j + 3) -= weight / bones;
  return s;
}

// Random example joint transforms around `rest`: rotated, scaled by 0.8–1.25 per axis and with the
// translation moved by up to ~0.2 (a "sampled" joint that is not rigid).
TransformList random_samples(const Transform& rest, int count, std::mt19937_64& engine) {
  std::uniform_real_distribution<double> scale(0.8, 1.25);
  std::normal_distribution<double> normal(0.0, 0.1);
  TransformList samples;
  for (int n = 0; n < count; ++n) {
    Transform L = rest;
    L.topLeftCorner<3, 3>() = rest.topLeftCorner<3, 3>() * random_rotation(engine) *
                              Eigen::Vector3d(scale(engine), scale(engine), scale(engine)).asDiagonal();
    L.topRightCorner<3, 1>() += Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    samples.push_back(L);
  }
  return samples;
}

// A 7-bone skeleton with non-identity (and one non-uniformly scaled) rest frames and every joint
// model. Axis-range joints hang below a sampled, scaling joint and below the scaled rest frame, so
// E[L̄ᵀ A L̄] is needed with A ≠ λI (where eqs. 3.13 and 3.15 alone would not be exact):
//   0 root ─ 1 sampled ─ 2 axis range ─ 3 uniform
//          │          └ 4 axis range (scaled rest) ─ 5 fixed
//          └ 6 sampled
struct MixedRig {
  Skeleton skeleton;
  std::vector<JointDistribution> distributions;
};

MixedRig mixed_rig(uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  MixedRig rig;
  rig.skeleton.parents = {-1, 0, 1, 2, 1, 4, 0};
  rig.skeleton.rest.assign(7, Transform::Identity());
  for (size_t j = 1; j < 7; ++j) {
    const Eigen::Vector3d offset = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
    const Eigen::Vector3d joint =
        rig.skeleton.rest[static_cast<size_t>(rig.skeleton.parents[j])].topRightCorner<3, 1>() + offset;
    rig.skeleton.rest[j] = make_transform(random_rotation(engine), joint);
  }
  rig.skeleton.rest[4].topLeftCorner<3, 3>() *= Eigen::Vector3d(1.3, 0.8, 1.1).asDiagonal();
  const TransformList rest = rest_joint_transforms(rig.skeleton);
  const Eigen::Vector3d axis = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
  rig.distributions = {fixed_joint(),
                       sampled_joint(random_samples(rest[1], 12, engine)),
                       axis_range_joint(axis, -0.4, 1.3),
                       uniform_rotation_joint(),
                       axis_range_joint(Eigen::Vector3d::UnitY(), 0.5, 2.9),
                       fixed_joint(),
                       sampled_joint(random_samples(rest[6], 5, engine))};
  return rig;
}

// Asserts that ‖s‖²₂,₂ equals the Monte-Carlo mean of ‖G s‖² over `count` poses within four
// standard errors of that mean.
void expect_l22_matches_monte_carlo(const Skeleton& skeleton, const std::vector<JointDistribution>& distributions,
                                    const std::vector<Eigen::VectorXd>& vectors, uint64_t seed, int count = 20000) {
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(skeleton, distributions);
  ASSERT_TRUE(metrics.ok()) << metrics.error().message;
  std::vector<std::vector<double>> squares(vectors.size());
  std::mt19937_64 engine(seed);
  for (int n = 0; n < count; ++n) {
    const Eigen::MatrixXd G = animation_matrix(sample_pose(skeleton, distributions, engine));
    for (size_t k = 0; k < vectors.size(); ++k) squares[k].push_back((G * vectors[k]).squaredNorm());
  }
  for (size_t k = 0; k < vectors.size(); ++k) {
    double mean = 0, variance = 0;
    for (const double x : squares[k]) mean += x;
    mean /= count;
    for (const double x : squares[k]) variance += (x - mean) * (x - mean);
    variance /= count - 1;
    const double standard_error = std::sqrt(variance / count);
    const Result<double> norm = l22_norm(*metrics, vectors[k]);
    ASSERT_TRUE(norm.ok()) << norm.error().message;
    EXPECT_NEAR(*norm * *norm, mean, 4 * standard_error + 1e-12) << "vector " << k << ", SE " << standard_error;
  }
}

// --- L2,2 against Monte Carlo ------------------------------------------------------------------

TEST(MetricsL22Test, UniformRotationsMatchMonteCarlo) {
  const Skeleton skeleton = random_skeleton(6, 1);
  const std::vector<JointDistribution> distributions(6, uniform_rotation_joint());
  std::vector<JointDistribution> with_fixed_root = distributions;
  with_fixed_root[0] = fixed_joint();
  const AnimationSpaceModel model = random_model(skeleton, 20, 2);
  std::mt19937_64 engine(3);
  std::vector<Eigen::VectorXd> vectors = {dense_position(model, 0) - dense_position(model, 1),
                                          dense_position(model, 5) - dense_position(model, 17),
                                          random_vector(6, engine)};
  expect_l22_matches_monte_carlo(skeleton, with_fixed_root, vectors, 4);
}

TEST(MetricsL22Test, AxisRangeRotationsMatchMonteCarlo) {
  Skeleton skeleton = random_skeleton(5, 5);
  std::mt19937_64 engine(6);
  skeleton.rest[2].topLeftCorner<3, 3>() = random_rotation(engine);
  std::normal_distribution<double> normal;
  std::vector<JointDistribution> distributions = {fixed_joint()};
  const double ranges[4][2] = {{-0.3, 1.2}, {0.5, 2.5}, {-kPi, kPi}, {1.0, 1.1}};
  for (const auto& range : ranges) {
    const Eigen::Vector3d axis = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
    distributions.push_back(axis_range_joint(axis, range[0], range[1]));
  }
  const AnimationSpaceModel model = random_model(skeleton, 20, 7);
  const std::vector<Eigen::VectorXd> vectors = {dense_position(model, 2) - dense_position(model, 3),
                                                dense_position(model, 11) - dense_position(model, 19),
                                                random_vector(5, engine)};
  expect_l22_matches_monte_carlo(skeleton, distributions, vectors, 8);
}

TEST(MetricsL22Test, MixedSkeletonMatchesMonteCarlo) {
  const MixedRig rig = mixed_rig(9);
  const AnimationSpaceModel model = random_model(rig.skeleton, 30, 10);
  std::mt19937_64 engine(11);
  std::vector<Eigen::VectorXd> vectors = {dense_position(model, 0) - dense_position(model, 1),
                                          dense_position(model, 7) - dense_position(model, 23),
                                          random_vector(7, engine), random_vector(7, engine)};
  // Pure directions on the uniform joint 3 and the axis-range joint 4: ‖G s‖² = ‖Ḡ_j u‖², which
  // isolates E[Ḡ_jᵀḠ_j] below the scaling ancestors.
  for (const int bone : {3, 4}) {
    vectors.push_back(Eigen::VectorXd::Zero(28));
    vectors.back().segment<3>(4 * bone) << 1.0, -2.0, 0.5;
  }
  expect_l22_matches_monte_carlo(rig.skeleton, rig.distributions, vectors, 12);
}

// With every joint fixed, E[‖G s‖²] is the rest-pose length: the Euclidean norm (§3.3.1).
TEST(MetricsL22Test, FixedSkeletonGivesRestPoseEuclideanNorm) {
  const MixedRig rig = mixed_rig(13);
  const std::vector<JointDistribution> fixed(7, fixed_joint());
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(rig.skeleton, fixed);
  ASSERT_TRUE(metrics.ok()) << metrics.error().message;
  const Eigen::MatrixXd G_rest = animation_matrix(rig.skeleton.rest);
  std::mt19937_64 engine(14);
  for (int k = 0; k < 5; ++k) {
    const Eigen::VectorXd s = random_vector(7, engine);
    const double euclidean = (G_rest * s).norm();
    EXPECT_NEAR(*l22_norm(*metrics, s), euclidean, 1e-10 * euclidean);
    // The bound holds in the rest pose too (it is only as tight as spheres allow).
    EXPECT_GE(*l2inf_norm(rig.skeleton, *metrics, s), euclidean * (1 - 1e-12));
  }
}

// Sparse and dense forms agree, and the inner product is the polarisation of the norm.
TEST(MetricsL22Test, SparseDenseAndInnerProductAgree) {
  const MixedRig rig = mixed_rig(15);
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(rig.skeleton, rig.distributions);
  ASSERT_TRUE(metrics.ok());
  const AnimationSpaceModel model = random_model(rig.skeleton, 40, 16);
  for (int i = 0; i + 3 < model.vertex_count(); i += 4) {
    const SparseAnimationVector s = vertex_difference(model, i, i + 1);
    const SparseAnimationVector t = vertex_difference(model, i + 2, i + 3);
    const Eigen::VectorXd s_dense = dense_position(model, i) - dense_position(model, i + 1);
    const Eigen::VectorXd t_dense = dense_position(model, i + 2) - dense_position(model, i + 3);
    const double ns = *l22_norm(*metrics, s_dense), nt = *l22_norm(*metrics, t_dense);
    EXPECT_NEAR(*l22_norm(*metrics, s), ns, 1e-12 * (1 + ns));
    const double inner = *l22_inner_product(*metrics, s, t);
    EXPECT_NEAR(inner, *l22_inner_product(*metrics, s_dense, t_dense), 1e-10 * (1 + std::abs(inner)));
    const double sum = *l22_norm(*metrics, Eigen::VectorXd(s_dense + t_dense));
    EXPECT_NEAR(inner, 0.5 * (sum * sum - ns * ns - nt * nt), 1e-9 * (1 + sum * sum));
    EXPECT_NEAR(*l2inf_norm(rig.skeleton, *metrics, s), *l2inf_norm(rig.skeleton, *metrics, s_dense), 1e-12 * (1 + ns));
  }
}

// P is symmetric positive semi-definite; C = P^½ maps the L2,2 inner product to the dot product;
// and the b − 1 vectors of Appendix B.3 (G r = 0 in every pose) have zero length in both norms.
TEST(MetricsL22Test, PIsPsdAndNormalisedSpaceReproducesInnerProduct) {
  const MixedRig rig = mixed_rig(17);
  std::vector<JointDistribution> rotations = rig.distributions;
  rotations[1] = uniform_rotation_joint();
  rotations[6] = axis_range_joint(Eigen::Vector3d::UnitX(), 0, 1);  // all translations fixed
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(rig.skeleton, rotations);
  ASSERT_TRUE(metrics.ok());
  const Eigen::MatrixXd& P = metrics->P;
  EXPECT_LT((P - P.transpose()).cwiseAbs().maxCoeff(), 1e-12 * P.cwiseAbs().maxCoeff());
  const Eigen::VectorXd eigenvalues = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(P).eigenvalues();
  EXPECT_GT(eigenvalues.minCoeff(), -1e-10 * eigenvalues.maxCoeff());

  const Result<Eigen::MatrixXd> C = normalised_animation_space_matrix(P);
  ASSERT_TRUE(C.ok()) << C.error().message;
  std::mt19937_64 engine(18);
  for (int k = 0; k < 5; ++k) {
    const Eigen::VectorXd s = random_vector(7, engine), t = random_vector(7, engine);
    const double norm = *l22_norm(*metrics, s);
    EXPECT_NEAR((*C * s).norm(), norm, 1e-9 * (1 + norm));
    EXPECT_NEAR((*C * s).dot(*C * t), *l22_inner_product(*metrics, s, t), 1e-9 * (1 + norm * norm));
  }

  // r = 1 on bone i minus (L̲̂_i, 1) on φ(i): G_i (0,0,0,1) = G_φ(i) (L̲̂_i, 1) when translations are fixed.
  const TransformList rest = rest_joint_transforms(rig.skeleton);
  int null_vectors = 0;
  for (int i = 1; i < 7; ++i) {
    Eigen::VectorXd r = Eigen::VectorXd::Zero(28);
    r(4 * i + 3) = 1;
    const int parent = rig.skeleton.parents[static_cast<size_t>(i)];
    r.segment<3>(4 * parent) = -rest[static_cast<size_t>(i)].topRightCorner<3, 1>();
    r(4 * parent + 3) -= 1;
    EXPECT_LT(*l22_norm(*metrics, r), 1e-6) << i;
    EXPECT_LT(*l2inf_norm(rig.skeleton, *metrics, r), 1e-12) << i;
    ++null_vectors;
  }
  int zero_eigenvalues = 0;
  for (Eigen::Index k = 0; k < eigenvalues.size(); ++k) zero_eigenvalues += eigenvalues(k) < 1e-10 * eigenvalues.maxCoeff();
  EXPECT_GE(zero_eigenvalues, null_vectors);
}

// --- Sampled from poses ------------------------------------------------------------------------

TEST(MetricsSampledTest, PoseAveragedPEqualsMeanOverThePoses) {
  const MixedRig rig = mixed_rig(19);
  std::mt19937_64 engine(20);
  std::vector<TransformList> poses;
  for (int n = 0; n < 50; ++n) poses.push_back(sample_pose(rig.skeleton, rig.distributions, engine));
  const Result<AnimationSpaceMetrics> metrics = metrics_from_poses(rig.skeleton, poses);
  ASSERT_TRUE(metrics.ok()) << metrics.error().message;
  for (int k = 0; k < 4; ++k) {
    const Eigen::VectorXd s = random_vector(7, engine);
    double mean = 0, largest = 0;
    for (const TransformList& pose : poses) {
      const double length = (animation_matrix(pose) * s).norm();
      mean += length * length / static_cast<double>(poses.size());
      largest = std::max(largest, length);
    }
    const double norm = *l22_norm(*metrics, s);
    EXPECT_NEAR(norm * norm, mean, 1e-10 * (1 + mean));
    EXPECT_GE(*l2inf_norm(rig.skeleton, *metrics, s), largest * (1 - 1e-12));
  }
}

// With a single moving joint there is nothing to be independent of: both sampled routes agree.
TEST(MetricsSampledTest, PerJointSamplesEqualPoseAverageForOneJoint) {
  Skeleton skeleton = random_skeleton(2, 21);
  std::mt19937_64 engine(22);
  const TransformList rest = rest_joint_transforms(skeleton);
  std::vector<TransformList> poses;
  for (const Transform& L : random_samples(rest[1], 30, engine)) poses.push_back({Transform::Identity(), L});
  const Result<std::vector<JointDistribution>> distributions = sampled_joint_distributions(skeleton, poses);
  ASSERT_TRUE(distributions.ok()) << distributions.error().message;
  const Result<AnimationSpaceMetrics> per_joint = metrics_from_joint_distributions(skeleton, *distributions);
  const Result<AnimationSpaceMetrics> averaged = metrics_from_poses(skeleton, poses);
  ASSERT_TRUE(per_joint.ok() && averaged.ok());
  EXPECT_LT((per_joint->P - averaged->P).cwiseAbs().maxCoeff(), 1e-12 * averaged->P.cwiseAbs().maxCoeff());
}

// --- Eq. 3.14 ----------------------------------------------------------------------------------

TEST(MetricsAxisRotationTest, ClosedFormMatchesThesisAndQuadrature) {
  // Eq. 3.14 as printed, for the z axis.
  const double phi0 = -0.7, phi1 = 1.9, width = phi1 - phi0;
  Eigen::Matrix3d printed;
  printed << std::sin(phi1) - std::sin(phi0), std::cos(phi1) - std::cos(phi0), 0,  //
      std::cos(phi0) - std::cos(phi1), std::sin(phi1) - std::sin(phi0), 0,          //
      0, 0, width;
  printed /= width;
  EXPECT_LT((*expected_axis_rotation(Eigen::Vector3d::UnitZ(), phi0, phi1) - printed).cwiseAbs().maxCoeff(), 1e-14);

  // Any axis: composite Simpson quadrature of Rot(a, φ) (error ~ h⁴, far below 1e-10 here).
  std::mt19937_64 engine(23);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::Vector3d axis = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
    const double a = normal(engine), b = a + 4 * std::abs(normal(engine)) + 0.1;
    const int intervals = 2000;
    const double h = (b - a) / intervals;
    Eigen::Matrix3d integral = Eigen::Matrix3d::Zero();
    for (int k = 0; k <= intervals; ++k) {
      const double w = (k == 0 || k == intervals) ? 1 : (k % 2 ? 4 : 2);
      integral += w * Eigen::AngleAxisd(a + k * h, axis).toRotationMatrix();
    }
    integral *= h / 3 / (b - a);
    EXPECT_LT((*expected_axis_rotation(axis, a, b) - integral).cwiseAbs().maxCoeff(), 1e-10) << trial;
  }

  // A zero-width range is the rotation itself, and nearly zero width does not cancel.
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 2) / 3;
  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(0.7, axis).toRotationMatrix();
  EXPECT_LT((*expected_axis_rotation(axis, 0.7, 0.7) - rotation).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT((*expected_axis_rotation(axis, 0.7, 0.7 + 1e-9) - rotation).cwiseAbs().maxCoeff(), 1e-9);
}

// --- L2,∞ --------------------------------------------------------------------------------------

TEST(MetricsL2InfTest, BoundIsNeverExceeded) {
  const MixedRig rig = mixed_rig(24);
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(rig.skeleton, rig.distributions);
  ASSERT_TRUE(metrics.ok());
  const AnimationSpaceModel model = random_model(rig.skeleton, 30, 25);
  std::mt19937_64 engine(26);
  std::vector<Eigen::VectorXd> vectors = {random_vector(7, engine), random_vector(7, engine)};
  for (int i = 0; i + 1 < 30; i += 6) vectors.push_back(dense_position(model, i) - dense_position(model, i + 1));
  std::vector<double> bounds, largest(vectors.size(), 0.0);
  for (const Eigen::VectorXd& s : vectors) bounds.push_back(*l2inf_norm(rig.skeleton, *metrics, s));
  for (int n = 0; n < 10000; ++n) {
    const Eigen::MatrixXd G = animation_matrix(sample_pose(rig.skeleton, rig.distributions, engine));
    for (size_t k = 0; k < vectors.size(); ++k) largest[k] = std::max(largest[k], (G * vectors[k]).norm());
  }
  for (size_t k = 0; k < vectors.size(); ++k) EXPECT_LE(largest[k], bounds[k] * (1 + 1e-12)) << k;
}

// One uniformly rotating joint at t: the point q on bone 1 is ‖t + R q‖ from the origin, at most
// ‖t‖ + ‖q‖ and attained when R q ∥ t — the bound is exact.
TEST(MetricsL2InfTest, SingleJointBoundIsExact) {
  Skeleton skeleton = random_skeleton(2, 27, 1.5);
  const std::vector<JointDistribution> distributions = {fixed_joint(), uniform_rotation_joint()};
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(skeleton, distributions);
  ASSERT_TRUE(metrics.ok());
  const Eigen::Vector3d q(0.3, -0.4, 0.2);
  SparseAnimationVector s;
  s.bones = {0, 1};
  s.vectors.resize(4, 2);
  s.vectors.col(0) << 0, 0, 0, -1;
  s.vectors.col(1) << q, 1;
  const double t = skeleton.rest[1].topRightCorner<3, 1>().norm();
  EXPECT_NEAR(*l2inf_norm(skeleton, *metrics, s), t + q.norm(), 1e-12);
}

// A sampled joint whose translations vary: the point c on the root and q on bone 1 are
// ‖c − L̄ q − L̲‖ apart, and every sample must stay within the bound — also when c sits at the
// samples' mean translation, where only the translation radius r1 keeps the bound honest.
TEST(MetricsL2InfTest, SampledJointBoundCoversEverySample) {
  const Skeleton skeleton = random_skeleton(2, 49);
  std::mt19937_64 engine(50);
  const TransformList samples = random_samples(rest_joint_transforms(skeleton)[1], 20, engine);
  const Result<AnimationSpaceMetrics> metrics =
      metrics_from_joint_distributions(skeleton, {fixed_joint(), sampled_joint(samples)});
  ASSERT_TRUE(metrics.ok());
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Transform& L : samples) mean += L.topRightCorner<3, 1>() / static_cast<double>(samples.size());
  std::normal_distribution<double> normal;
  const Eigen::Vector3d random_point(normal(engine), normal(engine), normal(engine));
  for (const auto& [c, q] : {std::pair{mean, Eigen::Vector3d::Zero().eval()}, std::pair{mean, random_point},
                             std::pair{random_point, Eigen::Vector3d::Zero().eval()}}) {
    SparseAnimationVector s;
    s.bones = {0, 1};
    s.vectors.resize(4, 2);
    s.vectors.col(0) << c, 1;
    s.vectors.col(1) << -q, -1;
    const double bound = *l2inf_norm(skeleton, *metrics, s);
    for (const Transform& L : samples) {
      EXPECT_LE((c - L.topLeftCorner<3, 3>() * q - L.topRightCorner<3, 1>()).norm(), bound * (1 + 1e-12));
    }
  }
}

// A two-bone chain under uniform rotations: no sample exceeds the bound and the best of 10⁴
// random poses comes within 10 % of it (the bound is attained by the aligned pose).
TEST(MetricsL2InfTest, TwoBoneChainBoundIsTight) {
  Skeleton skeleton;
  skeleton.parents = {-1, 0, 1};
  skeleton.rest = {Transform::Identity(), make_transform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, 0, 0)),
                   make_transform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, 1, 0))};
  const std::vector<JointDistribution> distributions = {fixed_joint(), uniform_rotation_joint(),
                                                        uniform_rotation_joint()};
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(skeleton, distributions);
  ASSERT_TRUE(metrics.ok());
  Eigen::VectorXd s = Eigen::VectorXd::Zero(12);
  s(3) = -1;                              // the origin, on the root
  s.segment<4>(8) << 0.5, 0, 0, 1;        // (0.5, 0, 0) in bone 2's frame
  const double bound = *l2inf_norm(skeleton, *metrics, s);
  EXPECT_NEAR(bound, 1 + 1 + 0.5, 1e-12);  // bone lengths plus the offset
  std::mt19937_64 engine(28);
  double largest = 0;
  for (int n = 0; n < 10000; ++n) {
    largest = std::max(largest, (animation_matrix(sample_pose(skeleton, distributions, engine)) * s).norm());
  }
  EXPECT_LE(largest, bound * (1 + 1e-12));
  EXPECT_GE(largest, 0.9 * bound);
}

// --- Bounding sphere (§7.2) ------------------------------------------------------------------

TEST(MetricsBoundingSphereTest, ContainsEveryPoseAndCentresOnExpectedCentroid) {
  const Skeleton skeleton = random_skeleton(8, 29);
  std::vector<JointDistribution> distributions(8, uniform_rotation_joint());
  distributions[0] = fixed_joint();
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(skeleton, distributions);
  ASSERT_TRUE(metrics.ok());
  const AnimationSpaceModel model = random_model(skeleton, 150, 30);
  const Result<geometry::BoundingSphere> sphere = pose_bounding_sphere(model, *metrics);
  ASSERT_TRUE(sphere.ok()) << sphere.error().message;

  Eigen::MatrixXd points(4 * 8, model.vertex_count());  // animation-space positions as columns
  for (int i = 0; i < model.vertex_count(); ++i) points.col(i) = dense_position(model, i);
  std::mt19937_64 engine(31);
  double farthest = 0;
  Eigen::Vector3d centroid_sum = Eigen::Vector3d::Zero(), centroid_square = Eigen::Vector3d::Zero();
  const int poses = 10000;
  for (int n = 0; n < poses; ++n) {
    const Eigen::MatrixXd posed = animation_matrix(sample_pose(skeleton, distributions, engine)) * points;
    farthest = std::max(farthest, (posed.topRows<3>().colwise() - sphere->centre).colwise().norm().maxCoeff());
    const Eigen::Vector3d centroid = posed.topRows<3>().rowwise().mean();
    centroid_sum += centroid;
    centroid_square += centroid.cwiseAbs2();
  }
  EXPECT_LE(farthest, sphere->radius * (1 + 1e-12));
  EXPECT_GE(farthest, 0.5 * sphere->radius);  // not uselessly loose
  // The centre is the expected posed centroid under uniform rotations (Monte Carlo, 4 SE).
  const Eigen::Vector3d mean = centroid_sum / poses;
  const Eigen::Vector3d standard_error = ((centroid_square / poses - mean.cwiseAbs2()) / poses).cwiseSqrt();
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(sphere->centre(c), mean(c), 4 * standard_error(c) + 1e-12) << c;
}

// Bounds from sampled, scaling joints hold for every combination of the samples.
TEST(MetricsBoundingSphereTest, ContainsEveryPoseOfSampledScalingJoints) {
  const MixedRig rig = mixed_rig(32);
  const Result<AnimationSpaceMetrics> metrics = metrics_from_joint_distributions(rig.skeleton, rig.distributions);
  ASSERT_TRUE(metrics.ok());
  const AnimationSpaceModel model = random_model(rig.skeleton, 100, 33);
  const Result<geometry::BoundingSphere> sphere = pose_bounding_sphere(model, *metrics);
  ASSERT_TRUE(sphere.ok()) << sphere.error().message;
  Eigen::MatrixXd points(4 * 7, model.vertex_count());
  for (int i = 0; i < model.vertex_count(); ++i) points.col(i) = dense_position(model, i);
  std::mt19937_64 engine(34);
  double farthest = 0;
  for (int n = 0; n < 10000; ++n) {
    const Eigen::MatrixXd posed = animation_matrix(sample_pose(rig.skeleton, rig.distributions, engine)) * points;
    farthest = std::max(farthest, (posed.topRows<3>().colwise() - sphere->centre).colwise().norm().maxCoeff());
  }
  EXPECT_LE(farthest, sphere->radius * (1 + 1e-12));
}

// --- Transforms (§3.4) -------------------------------------------------------------------------

void expect_metrics_equal(const AnimationSpaceMetrics& actual, const AnimationSpaceMetrics& expected,
                          const std::string& what) {
  const double scale = expected.P.cwiseAbs().maxCoeff();
  EXPECT_LT((actual.P - expected.P).cwiseAbs().maxCoeff(), 1e-10 * scale) << what;
  ASSERT_EQ(actual.bone_count(), expected.bone_count());
  for (size_t j = 0; j < expected.expected_joints.size(); ++j) {
    const double joint_scale = 1 + expected.expected_joints[j].cwiseAbs().maxCoeff();
    EXPECT_LT((actual.expected_joints[j] - expected.expected_joints[j]).cwiseAbs().maxCoeff(), 1e-12 * joint_scale)
        << what << " E[L_" << j << "]";
    const JointBound& a = actual.joint_bounds[j];
    const JointBound& e = expected.joint_bounds[j];
    const double length = 1 + e.translation_centre.norm() + e.translation_radius;
    EXPECT_NEAR(a.linear_norm, e.linear_norm, 1e-12) << what << " bound " << j;
    EXPECT_LT((a.translation_centre - e.translation_centre).norm(), 1e-12 * length) << what << " bound " << j;
    EXPECT_NEAR(a.translation_radius, e.translation_radius, 1e-12 * length) << what << " bound " << j;
  }
}

TEST(MetricsTransformTest, ScalingMatchesRecomputationAndScalesPosedVertices) {
  for (const double scale : {1e-4, 2.5, 1e4}) {
    const MixedRig rig = mixed_rig(35);
    AnimationSpaceModel model = random_model(rig.skeleton, 40, 36);
    const AnimationSpaceModel original = model;
    AnimationSpaceMetrics metrics = *metrics_from_joint_distributions(rig.skeleton, rig.distributions);
    ASSERT_TRUE(scale_model(scale, model, metrics).ok());

    // The same distributions on a skeleton (and samples) with every translation scaled.
    MixedRig scaled = rig;
    for (Transform& rest : scaled.skeleton.rest) rest.topRightCorner<3, 1>() *= scale;
    for (JointDistribution& distribution : scaled.distributions) {
      for (Transform& L : distribution.samples) L.topRightCorner<3, 1>() *= scale;
    }
    for (size_t j = 0; j < rig.skeleton.rest.size(); ++j) {
      EXPECT_TRUE(model.skeleton.rest[j].isApprox(scaled.skeleton.rest[j], 1e-14)) << j;
    }
    const Result<AnimationSpaceMetrics> recomputed =
        metrics_from_joint_distributions(scaled.skeleton, scaled.distributions);
    ASSERT_TRUE(recomputed.ok());
    expect_metrics_equal(metrics, *recomputed, "scale " + std::to_string(scale));

    // Posed with joint translations scaled, every vertex is s·v.
    std::mt19937_64 engine(37);
    for (int n = 0; n < 5; ++n) {
      TransformList joints = joint_transforms(rig.skeleton, sample_pose(rig.skeleton, rig.distributions, engine));
      const Eigen::MatrixXd G = animation_matrix(global_transforms(rig.skeleton, joints));
      for (Transform& L : joints) L.topRightCorner<3, 1>() *= scale;
      const Eigen::MatrixXd G_scaled = animation_matrix(global_transforms(model.skeleton, joints));
      for (int i = 0; i < model.vertex_count(); ++i) {
        const Eigen::Vector4d v = G * dense_position(original, i);
        const Eigen::Vector4d v_scaled = G_scaled * dense_position(model, i);
        EXPECT_LT((v_scaled.head<3>() - scale * v.head<3>()).norm(), 1e-12 * scale * (1 + v.norm())) << i;
        EXPECT_NEAR(v_scaled(3), 1.0, 1e-12);
      }
    }
  }
}

Transform random_rigid(std::mt19937_64& engine) {
  std::normal_distribution<double> normal(0.0, 3.0);
  return make_transform(random_rotation(engine), Eigen::Vector3d(normal(engine), normal(engine), normal(engine)));
}

TEST(MetricsTransformTest, RigidTransformMatchesRecomputationAndMovesPosedVertices) {
  const MixedRig rig = mixed_rig(38);
  std::mt19937_64 engine(39);
  const Transform M = random_rigid(engine);
  AnimationSpaceModel model = random_model(rig.skeleton, 40, 40);
  const AnimationSpaceModel original = model;
  AnimationSpaceMetrics metrics = *metrics_from_joint_distributions(rig.skeleton, rig.distributions);
  ASSERT_TRUE(rigid_transform_model(M, model, metrics).ok());

  // The same distributions with every sub-root joint composed with M: Ĝ_j ← M Ĝ_j (j ≥ 1), and
  // the samples of sub-root sampled joints ← M L.
  MixedRig moved = rig;
  for (size_t j = 1; j < moved.skeleton.rest.size(); ++j) moved.skeleton.rest[j] = M * moved.skeleton.rest[j];
  for (size_t j = 1; j < moved.distributions.size(); ++j) {
    if (moved.skeleton.parents[j] != 0) continue;
    for (Transform& L : moved.distributions[j].samples) L = M * L;
  }
  for (size_t j = 0; j < rig.skeleton.rest.size(); ++j) {
    EXPECT_TRUE(model.skeleton.rest[j].isApprox(moved.skeleton.rest[j], 1e-14)) << j;
  }
  const Result<AnimationSpaceMetrics> recomputed = metrics_from_joint_distributions(moved.skeleton, moved.distributions);
  ASSERT_TRUE(recomputed.ok());
  expect_metrics_equal(metrics, *recomputed, "rigid");

  // Posed with sub-root joints composed with M, every vertex is M·v.
  for (int n = 0; n < 5; ++n) {
    TransformList joints = joint_transforms(rig.skeleton, sample_pose(rig.skeleton, rig.distributions, engine));
    const Eigen::MatrixXd G = animation_matrix(global_transforms(rig.skeleton, joints));
    for (size_t j = 1; j < joints.size(); ++j) {
      if (rig.skeleton.parents[j] == 0) joints[j] = M * joints[j];
    }
    const Eigen::MatrixXd G_moved = animation_matrix(global_transforms(model.skeleton, joints));
    for (int i = 0; i < model.vertex_count(); ++i) {
      const Eigen::Vector4d v = M * (G * dense_position(original, i));
      EXPECT_LT((G_moved * dense_position(model, i) - v).norm(), 1e-11 * (1 + v.norm())) << i;
    }
  }
}

// Eq. 3.33 needs only E[G_j] from P, so it is exact for a pose-averaged P with correlated joints.
TEST(MetricsTransformTest, RigidTransformOfPoseAveragedMetricsMatchesMovedPoses) {
  const MixedRig rig = mixed_rig(41);
  std::mt19937_64 engine(42);
  const Transform M = random_rigid(engine);
  std::vector<TransformList> poses, moved_poses;
  for (int n = 0; n < 40; ++n) {
    poses.push_back(sample_pose(rig.skeleton, rig.distributions, engine));
    moved_poses.push_back(poses.back());
    for (size_t j = 1; j < poses.back().size(); ++j) moved_poses.back()[j] = M * poses.back()[j];
  }
  AnimationSpaceModel model = random_model(rig.skeleton, 10, 43);
  AnimationSpaceMetrics metrics = *metrics_from_poses(rig.skeleton, poses);
  ASSERT_TRUE(rigid_transform_model(M, model, metrics).ok());
  const Result<AnimationSpaceMetrics> recomputed = metrics_from_poses(model.skeleton, moved_poses);
  ASSERT_TRUE(recomputed.ok());
  expect_metrics_equal(metrics, *recomputed, "rigid, pose-averaged");
}

// --- Bad input ---------------------------------------------------------------------------------

void expect_invalid(const Status& status, const std::string& fragment) {
  ASSERT_FALSE(status.ok()) << "expected an error mentioning '" << fragment << "'";
  EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(status.error().message.find(fragment), std::string::npos) << status.error().message;
}

template <typename T>
Status status_of(const Result<T>& result) {
  return result.ok() ? Status::Ok() : Status(result.error());
}

TEST(MetricsBadInputTest, RejectsMalformedDistributions) {
  const Skeleton skeleton = random_skeleton(3, 44);
  expect_invalid(status_of(metrics_from_joint_distributions(
                     skeleton, {fixed_joint(), axis_range_joint(Eigen::Vector3d::UnitX(), 1.0, 0.5), fixed_joint()})),
                 "bone 1: rotation range has φ0");
  expect_invalid(status_of(metrics_from_joint_distributions(
                     skeleton, {fixed_joint(), fixed_joint(), axis_range_joint(Eigen::Vector3d(1, 1, 0), 0, 1)})),
                 "bone 2: rotation axis has length 1.41");
  expect_invalid(status_of(metrics_from_joint_distributions(
                     skeleton, {fixed_joint(), axis_range_joint(Eigen::Vector3d::UnitX(), 0, NAN), fixed_joint()})),
                 "not finite");
  expect_invalid(status_of(metrics_from_joint_distributions(
                     skeleton, {uniform_rotation_joint(), fixed_joint(), fixed_joint()})),
                 "bone 0");
  expect_invalid(status_of(metrics_from_joint_distributions(skeleton, {fixed_joint(), fixed_joint()})),
                 "one joint distribution per bone (3), got 2");
  expect_invalid(status_of(metrics_from_joint_distributions(skeleton, {fixed_joint(), sampled_joint({}), fixed_joint()})),
                 "bone 1: sampled joint model has no samples");
  Transform bad = Transform::Identity();
  bad(3, 0) = 0.1;
  expect_invalid(status_of(metrics_from_joint_distributions(skeleton, {fixed_joint(), fixed_joint(), sampled_joint({bad})})),
                 "bone 2: sample 0 is not a finite affine");
  expect_invalid(status_of(expected_axis_rotation(Eigen::Vector3d::UnitZ(), 2, 1)), "φ0 = 2");
  expect_invalid(status_of(expected_axis_rotation(Eigen::Vector3d::Zero(), 0, 1)), "unit vector");

  // Example poses: none, wrong count, moving root.
  expect_invalid(status_of(metrics_from_poses(skeleton, {})), "no example poses");
  expect_invalid(status_of(metrics_from_poses(skeleton, {TransformList(2, Transform::Identity())})),
                 "pose 0: expected 3 bone transforms");
  TransformList moved_root = skeleton.rest;
  moved_root[0](0, 3) = 1;
  expect_invalid(status_of(sampled_joint_distributions(skeleton, {skeleton.rest, moved_root})),
                 "pose 1: transform of bone 0 (the root) must be the identity");
}

TEST(MetricsBadInputTest, RejectsMalformedVectors) {
  const Skeleton skeleton = random_skeleton(3, 45);
  const AnimationSpaceMetrics metrics =
      *metrics_from_joint_distributions(skeleton, {fixed_joint(), uniform_rotation_joint(), uniform_rotation_joint()});
  expect_invalid(status_of(l22_norm(metrics, Eigen::VectorXd(Eigen::VectorXd::Zero(8)))), "s has 8 entries, expected 4b = 12");
  Eigen::VectorXd weighted = Eigen::VectorXd::Zero(12);
  weighted(7) = 1;
  expect_invalid(status_of(l22_norm(metrics, weighted)), "s has weight 1");
  expect_invalid(status_of(l2inf_norm(skeleton, metrics, weighted)), "expected 0");
  expect_invalid(status_of(l22_inner_product(metrics, Eigen::VectorXd(Eigen::VectorXd::Zero(12)), weighted)),
                 "t has weight 1");
  Eigen::VectorXd nan = Eigen::VectorXd::Zero(12);
  nan(0) = NAN;
  expect_invalid(status_of(l22_norm(metrics, nan)), "NaN");

  SparseAnimationVector sparse;
  sparse.bones = {1, 3};
  sparse.vectors = Eigen::Matrix<double, 4, 2>::Zero();
  expect_invalid(status_of(l22_norm(metrics, sparse)), "bone 3 is outside 0 … 2");
  sparse.bones = {2, 1};
  expect_invalid(status_of(l2inf_norm(skeleton, metrics, sparse)), "strictly increasing");
  sparse.bones = {1};
  expect_invalid(status_of(l22_norm(metrics, sparse)), "1 bones but 2 4-vectors");

  expect_invalid(status_of(l2inf_norm(random_skeleton(4, 46), metrics, Eigen::VectorXd(Eigen::VectorXd::Zero(12)))),
                 "metrics are for 3 bones");
  Eigen::MatrixXd indefinite = Eigen::MatrixXd::Identity(4, 4);
  indefinite(2, 2) = -0.5;
  expect_invalid(status_of(normalised_animation_space_matrix(indefinite)), "not positive semi-definite");
  expect_invalid(status_of(normalised_animation_space_matrix(Eigen::MatrixXd::Zero(4, 3))), "expected square");
}

TEST(MetricsBadInputTest, RejectsBadTransformsAndLeavesModelUnchanged) {
  const Skeleton skeleton = random_skeleton(3, 47);
  AnimationSpaceModel model = random_model(skeleton, 5, 48);
  AnimationSpaceMetrics metrics =
      *metrics_from_joint_distributions(skeleton, {fixed_joint(), uniform_rotation_joint(), uniform_rotation_joint()});
  const AnimationSpaceModel model_before = model;
  const Eigen::MatrixXd P_before = metrics.P;
  expect_invalid(scale_model(0.0, model, metrics), "scale is 0");
  expect_invalid(scale_model(-2.0, model, metrics), "expected a finite factor > 0");
  expect_invalid(scale_model(INFINITY, model, metrics), "expected a finite factor > 0");
  Transform shear = Transform::Identity();
  shear(0, 1) = 0.3;
  expect_invalid(rigid_transform_model(shear, model, metrics), "not a rotation");
  Transform reflection = Transform::Identity();
  reflection(2, 2) = -1;
  expect_invalid(rigid_transform_model(reflection, model, metrics), "det = -1");
  AnimationSpaceMetrics wrong = metrics;
  wrong.P.conservativeResize(8, 8);
  expect_invalid(rigid_transform_model(Transform::Identity(), model, wrong), "metrics are for 3 bones");
  EXPECT_EQ(model.positions, model_before.positions);
  EXPECT_EQ(metrics.P, P_before);
  for (size_t j = 0; j < model.skeleton.rest.size(); ++j) EXPECT_EQ(model.skeleton.rest[j], model_before.skeleton.rest[j]);

  AnimationSpaceModel empty;
  empty.skeleton = skeleton;
  expect_invalid(status_of(pose_bounding_sphere(empty, metrics)), "no vertices");
}

}  // namespace
}  // namespace animspace::animation_space
