// Tests of the least-squares rigid fit. Known motions are built from quaternions and explicit
// axis rotations (never through the SVD under test); optimality in the reflection case is
// checked against many random rotations.
#include "core/geometry/rigid_fit.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <gtest/gtest.h>

namespace animspace::geometry {
namespace {

using Eigen::Index;
using Eigen::Matrix3d;
using Eigen::Matrix3Xd;
using Eigen::Vector3d;
using Eigen::VectorXd;

Matrix3Xd gaussian_points(Index N, uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  Matrix3Xd P(3, N);
  for (Index i = 0; i < N; ++i) P.col(i) = Vector3d(normal(engine), normal(engine), normal(engine));
  return P;
}

Matrix3d random_rotation(uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  Eigen::Quaterniond q(normal(engine), normal(engine), normal(engine), normal(engine));
  return q.normalized().toRotationMatrix();
}

Matrix3d rotation_z(double angle) {
  Matrix3d r;
  r << std::cos(angle), -std::sin(angle), 0,  //
      std::sin(angle), std::cos(angle), 0,    //
      0, 0, 1;
  return r;
}

Matrix3Xd moved(const Matrix3Xd& P, const Matrix3d& R, const Vector3d& t) {
  return (R * P).colwise() + t;
}

double cost(const RigidTransform& T, const Matrix3Xd& from, const Matrix3Xd& to) {
  return (moved(from, T.rotation, T.translation) - to).squaredNorm();
}

void expect_proper_rotation(const Matrix3d& R) {
  EXPECT_TRUE(R.allFinite());
  EXPECT_LT((R.transpose() * R - Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
}

TEST(RigidFit, RecoversAKnownMotionFromNoiselessPoints) {
  struct Case {
    double scale;   // of the point cloud
    double offset;  // distance of the cloud from the origin
    double tolerance;
  };
  for (const Case c : {Case{1.0, 0.0, 1e-10}, Case{1e-4, 0.0, 1e-10}, Case{1e4, 0.0, 1e-10},
                       Case{1.0, 1e5, 1e-8}}) {
    for (const uint64_t seed : {1u, 2u, 3u}) {
      SCOPED_TRACE(::testing::Message() << "scale " << c.scale << ", offset " << c.offset
                                        << ", seed " << seed);
      const Matrix3Xd from =
          (c.scale * gaussian_points(30, seed)).colwise() + Vector3d::Constant(c.offset);
      const Matrix3d R = random_rotation(seed + 10);
      const Vector3d t = c.scale * Vector3d(0.3, -2.0, 5.0);
      const RigidTransform fit = fit_rigid(from, moved(from, R, t));
      expect_proper_rotation(fit.rotation);
      EXPECT_LT((fit.rotation - R).cwiseAbs().maxCoeff(), c.tolerance);
      EXPECT_LT((fit.translation - t).cwiseAbs().maxCoeff(),
                c.tolerance * (c.scale + c.offset));
    }
  }
}

TEST(RigidFit, MirrorImageGivesTheBestProperRotation) {
  const Matrix3Xd from = gaussian_points(40, 21);
  Matrix3Xd to = from;
  to.row(2) *= -1.0;  // a reflection through z = 0: the best orthogonal fit has det = -1
  const RigidTransform fit = fit_rigid(from, to);
  expect_proper_rotation(fit.rotation);
  const double best = cost(fit, from, to);
  for (uint64_t seed = 0; seed < 2000; ++seed) {
    RigidTransform other;
    other.rotation = random_rotation(1000 + seed);
    other.translation = to.rowwise().mean() - other.rotation * from.rowwise().mean();
    EXPECT_LE(best, cost(other, from, to) + 1e-9) << "seed " << seed;
  }
}

TEST(RigidFit, ZeroWeightOutliersAreIgnored) {
  const Matrix3Xd inliers = gaussian_points(20, 31);
  const Matrix3d R = random_rotation(32);
  const Vector3d t(1.0, 2.0, 3.0);
  Matrix3Xd from(3, 26), to(3, 26);
  from << inliers, gaussian_points(6, 33);
  to << moved(inliers, R, t), 100.0 * gaussian_points(6, 34);
  // Zero-weight points may hold anything, even NaN.
  to(0, 25) = std::numeric_limits<double>::quiet_NaN();
  VectorXd weights = VectorXd::Ones(26);
  weights.tail(6).setZero();
  const RigidTransform fit = fit_rigid(from, to, weights);
  EXPECT_LT((fit.rotation - R).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_LT((fit.translation - t).cwiseAbs().maxCoeff(), 1e-10);
}

TEST(RigidFit, IntegerWeightsEqualRepeatedPoints) {
  // Noisy data, so the fit is a genuine compromise.
  const Matrix3Xd from = gaussian_points(10, 41);
  const Matrix3Xd to = moved(from, random_rotation(42), Vector3d(0, 1, 0)) +
                       0.1 * gaussian_points(10, 43);
  VectorXd weights(10);
  weights << 1, 2, 3, 1, 1, 2, 1, 3, 1, 1;
  Matrix3Xd from_repeated(3, static_cast<Index>(weights.sum())),
      to_repeated(3, static_cast<Index>(weights.sum()));
  Index next = 0;
  for (Index i = 0; i < 10; ++i) {
    for (int copy = 0; copy < static_cast<int>(weights(i)); ++copy, ++next) {
      from_repeated.col(next) = from.col(i);
      to_repeated.col(next) = to.col(i);
    }
  }
  const RigidTransform weighted = fit_rigid(from, to, weights);
  const RigidTransform repeated = fit_rigid(from_repeated, to_repeated);
  EXPECT_LT((weighted.rotation - repeated.rotation).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((weighted.translation - repeated.translation).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(RigidFit, CollinearPointsGiveTheSmallestRotationBetweenTheLines) {
  // Points on the x axis mapped onto a line along y: the smallest rotation is 90° about z.
  Matrix3Xd from(3, 5);
  for (Index i = 0; i < 5; ++i) from.col(i) = Vector3d(static_cast<double>(i) - 1.0, 0.0, 0.0);
  const Matrix3d Rz = rotation_z(std::numbers::pi / 2.0);
  const Vector3d t(1.0, 1.0, 1.0);
  const RigidTransform fit = fit_rigid(from, moved(from, Rz, t));
  expect_proper_rotation(fit.rotation);
  EXPECT_LT((fit.rotation - Rz).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT(cost(fit, from, moved(from, Rz, t)), 1e-20);

  // The line reversed: a half turn; points still land exactly.
  Matrix3Xd reversed = -from;
  reversed.colwise() += Vector3d(0.0, 0.0, 2.0);
  const RigidTransform flip = fit_rigid(from, reversed);
  expect_proper_rotation(flip.rotation);
  EXPECT_LT(cost(flip, from, reversed), 1e-20);
}

TEST(RigidFit, DegenerateInputsGiveAFiniteProperRotation) {
  const Vector3d a(1.0, 2.0, 3.0), b(-4.0, 0.5, 2.0);
  // One point, and several coincident ones: identity, translation between the points.
  for (const Index N : {1, 4}) {
    SCOPED_TRACE(N);
    const RigidTransform fit =
        fit_rigid(a.replicate(1, N), b.replicate(1, N));
    EXPECT_EQ(fit.rotation, Matrix3d::Identity());
    EXPECT_LT((fit.translation - (b - a)).norm(), 1e-14);
  }
  // No points, and only zero weights: the identity.
  const RigidTransform empty = fit_rigid(Matrix3Xd(3, 0), Matrix3Xd(3, 0));
  EXPECT_EQ(empty.rotation, Matrix3d::Identity());
  EXPECT_EQ(empty.translation, Vector3d::Zero());
  const RigidTransform unweighted =
      fit_rigid(gaussian_points(5, 51), gaussian_points(5, 52), VectorXd::Zero(5));
  EXPECT_EQ(unweighted.rotation, Matrix3d::Identity());
  EXPECT_EQ(unweighted.translation, Vector3d::Zero());
  // Spread-out sets whose cross-covariance vanishes: every rotation fits equally.
  Matrix3Xd cross(3, 4), poles(3, 4);
  cross << 1, -1, 0, 0,  //
      0, 0, 1, -1,       //
      0, 0, 0, 0;
  poles << 0, 0, 0, 0,  //
      0, 0, 0, 0,       //
      1, 1, -1, -1;
  const RigidTransform uncorrelated = fit_rigid(cross, poles);
  expect_proper_rotation(uncorrelated.rotation);
  EXPECT_TRUE(uncorrelated.translation.allFinite());
  // Planar points: unique and exact.
  Matrix3Xd planar = gaussian_points(12, 53);
  planar.row(2).setZero();
  const Matrix3d R = random_rotation(54);
  const RigidTransform plane = fit_rigid(planar, moved(planar, R, Vector3d::Zero()));
  EXPECT_LT((plane.rotation - R).cwiseAbs().maxCoeff(), 1e-10);
}

TEST(RigidTransform, InverseUndoesTheTransform) {
  RigidTransform T;
  T.rotation = random_rotation(61);
  T.translation = Vector3d(3.0, -1.0, 0.25);
  const RigidTransform inverse = T.inverse();
  const Matrix3Xd points = gaussian_points(10, 62);
  for (Index i = 0; i < points.cols(); ++i) {
    EXPECT_LT((inverse.apply(T.apply(points.col(i))) - points.col(i)).norm(), 1e-14);
    EXPECT_LT((T.apply(inverse.apply(points.col(i))) - points.col(i)).norm(), 1e-14);
  }
}

TEST(RigidTransform, FrameAndInPlaceApplicationMatchPointByPoint) {
  RigidTransform T;
  T.rotation = random_rotation(71);
  T.translation = Vector3d(-2.0, 0.5, 1.0);
  const Matrix3Xd points = gaussian_points(7, 72);
  // The frame layout x0 y0 z0 x1 …: a column-major 3 × N matrix's storage.
  const VectorXd frame = Eigen::Map<const VectorXd>(points.data(), points.size());
  const VectorXd moved_frame = transform_frame(T, frame);
  Matrix3Xd in_place = points;
  apply_rigid(T, in_place);
  ASSERT_EQ(moved_frame.size(), 21);
  for (Index i = 0; i < points.cols(); ++i) {
    const Vector3d expected = T.apply(points.col(i));
    EXPECT_LT((moved_frame.segment<3>(3 * i) - expected).norm(), 1e-14) << "point " << i;
    EXPECT_LT((in_place.col(i) - expected).norm(), 1e-14) << "point " << i;
  }
  EXPECT_EQ(transform_frame(T, VectorXd(0)).size(), 0);
}

}  // namespace
}  // namespace animspace::geometry
