// Tests of the bending-arm demo. Expected values come from the geometry of a cylinder and of
// rotations, written out here independently of the code under test (explicit sines and
// cosines, never the module's own transforms).
#include "core/demo/bending_arm.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "tests/support/test_support.h"

namespace animspace::demo {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

Eigen::Vector3d point(const PointMatrix& P, Eigen::Index i) {
  return P.row(i).cast<double>().transpose();
}

// Volume enclosed by a closed mesh: Σ a·(b×c)/6 over faces, positive when faces are
// counter-clockwise seen from outside (divergence theorem).
double signed_volume(const PointMatrix& V, const FaceMatrix& F) {
  double volume = 0.0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = point(V, F(f, 0)), b = point(V, F(f, 1)), c = point(V, F(f, 2));
    volume += a.dot(b.cross(c)) / 6.0;
  }
  return volume;
}

double max_distance(const PointMatrix& A, const PointMatrix& B) {
  return (A.cast<double>() - B.cast<double>()).rowwise().norm().maxCoeff();
}

// Index of the vertex on ring k at segment s (the layout documented in bending_arm.h).
Eigen::Index ring_vertex(const BendingArmOptions& o, int k, int s) { return k * o.segments + s; }

// ---------------------------------------------------------------------------------------------
// Mesh

TEST(BendingArmMesh, IsClosedManifoldOutwardAndHasTheInscribedPrismVolume) {
  struct Case {
    int rings, segments;
    double length, radius;
  };
  for (const Case c : {Case{48, 24, 2.0, 0.18}, Case{2, 3, 1.0, 1.0}, Case{7, 9, 3.0, 0.05}}) {
    SCOPED_TRACE(::testing::Message() << c.rings << " rings, " << c.segments << " segments");
    BendingArmOptions o;
    o.rings = c.rings;
    o.segments = c.segments;
    o.length = c.length;
    o.radius = c.radius;
    o.elbow_zone_width = c.length / 5.0;
    const TriangleMesh mesh = make_arm_mesh(o);
    ASSERT_EQ(mesh.V.rows(), c.rings * c.segments + 2);
    ASSERT_EQ(mesh.F.rows(), 2 * c.segments * c.rings);

    // Manifold and consistently oriented: every directed edge occurs once and its reverse once,
    // so each undirected edge has exactly two faces that traverse it in opposite directions.
    std::map<std::pair<int32_t, int32_t>, int> directed;
    for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
      for (int e = 0; e < 3; ++e) {
        const int32_t a = mesh.F(f, e), b = mesh.F(f, (e + 1) % 3);
        ASSERT_NE(a, b) << "degenerate face " << f;
        ASSERT_GE(a, 0);
        ASSERT_LT(a, mesh.V.rows());
        ++directed[{a, b}];
      }
    }
    for (const auto& [edge, count] : directed) {
      EXPECT_EQ(count, 1) << edge.first << "->" << edge.second;
      const auto reverse = directed.find({edge.second, edge.first});
      ASSERT_NE(reverse, directed.end()) << "boundary edge " << edge.first << "-" << edge.second;
      EXPECT_EQ(reverse->second, 1);
    }
    // Euler characteristic of a sphere-like closed surface.
    const auto edges = static_cast<Eigen::Index>(directed.size() / 2);
    EXPECT_EQ(mesh.V.rows() - edges + mesh.F.rows(), 2);

    // The mesh is exactly the prism over the inscribed regular n-gon: area (n/2) r² sin(2π/n).
    const double n = c.segments;
    const double prism = 0.5 * n * c.radius * c.radius * std::sin(2.0 * kPi / n) * c.length;
    const double volume = signed_volume(mesh.V, mesh.F);
    EXPECT_GT(volume, 0.0) << "faces are oriented inwards";
    EXPECT_NEAR(volume, prism, 1e-5 * prism);
    EXPECT_LT(volume, kPi * c.radius * c.radius * c.length);
  }
}

TEST(BendingArmMesh, VerticesLieOnTheCylinderAndItsCaps) {
  const BendingArmOptions o;
  const TriangleMesh mesh = make_arm_mesh(o);
  for (int k = 0; k < o.rings; ++k) {
    for (int s = 0; s < o.segments; ++s) {
      const Eigen::Vector3d v = point(mesh.V, ring_vertex(o, k, s));
      EXPECT_NEAR(v.x(), o.length * k / (o.rings - 1), 1e-6);
      EXPECT_NEAR(std::hypot(v.y(), v.z()), o.radius, 1e-6);
      // φ measured from +y towards +z.
      const double phi = 2.0 * kPi * s / o.segments;
      EXPECT_NEAR(v.y(), o.radius * std::cos(phi), 1e-6);
      EXPECT_NEAR(v.z(), o.radius * std::sin(phi), 1e-6);
    }
  }
  const Eigen::Index shoulder = o.rings * o.segments;
  EXPECT_EQ(point(mesh.V, shoulder), Eigen::Vector3d(0, 0, 0));
  EXPECT_EQ(point(mesh.V, shoulder + 1), Eigen::Vector3d(o.length, 0, 0));
}

// ---------------------------------------------------------------------------------------------
// Rig: weights and transforms

TEST(BendingArmRig, WeightsArePartitionOfUnityLocalAndSymmetricAboutTheElbow) {
  BendingArmOptions o;
  o.elbow_zone_width = 0.5;
  const double elbow = o.length / 2.0;
  const double half_zone = o.elbow_zone_width / 2.0;
  // Sample x finely along the arm (independent of the mesh's ring spacing).
  const int samples = 401;
  PointMatrix X = PointMatrix::Zero(samples, 3);
  for (int i = 0; i < samples; ++i) X(i, 0) = static_cast<float>(o.length * i / (samples - 1));
  const Eigen::MatrixXd W = arm_skinning_weights(X, o);
  ASSERT_EQ(W.rows(), samples);
  ASSERT_EQ(W.cols(), 2);
  for (int i = 0; i < samples; ++i) {
    const double x = X(i, 0);
    EXPECT_GE(W(i, kUpperArm), 0.0);
    EXPECT_LE(W(i, kUpperArm), 1.0);
    EXPECT_GE(W(i, kForearm), 0.0);
    EXPECT_LE(W(i, kForearm), 1.0);
    EXPECT_NEAR(W.row(i).sum(), 1.0, 1e-15);
    if (x <= elbow - half_zone) {
      EXPECT_EQ(W(i, kUpperArm), 1.0) << "x = " << x;
    }
    if (x >= elbow + half_zone) {
      EXPECT_EQ(W(i, kForearm), 1.0) << "x = " << x;
    }
    if (i > 0) {
      EXPECT_GE(W(i, kForearm), W(i - 1, kForearm)) << "forearm weight must not fall along the arm";
    }
  }
  // A falloff centred on the elbow: w(e + d) = 1 - w(e - d), and 1/2 at the elbow itself.
  PointMatrix pair(2, 3);
  for (const double d : {0.0, 0.05, 0.1, 0.2, 0.24}) {
    pair << static_cast<float>(elbow + d), 0, 0, static_cast<float>(elbow - d), 0, 0;
    const Eigen::MatrixXd w = arm_skinning_weights(pair, o);
    EXPECT_NEAR(w(0, kForearm) + w(1, kForearm), 1.0, 1e-6) << "d = " << d;
  }
  pair << static_cast<float>(elbow), 0, 0, 0, 0, 0;
  EXPECT_DOUBLE_EQ(arm_skinning_weights(pair, o)(0, kForearm), 0.5);
}

TEST(BendingArmRig, RestTransformsPlaceTheElbowAndPosesAreRigid) {
  const BendingArmOptions o;
  const auto rest = rest_bone_transforms(o);
  EXPECT_EQ(rest[kUpperArm], Eigen::Matrix4d::Identity());
  Eigen::Matrix4d elbow = Eigen::Matrix4d::Identity();
  elbow(0, 3) = o.length / 2.0;
  EXPECT_EQ(rest[kForearm], elbow);
  EXPECT_EQ(kArmParents[kUpperArm], -1);
  EXPECT_EQ(kArmParents[kForearm], kUpperArm);

  // At the rest pose G_j = Ĝ_j.
  const auto G0 = bone_transforms(ArmPose{}, o);
  EXPECT_EQ(G0[kUpperArm], rest[kUpperArm]);
  EXPECT_EQ(G0[kForearm], rest[kForearm]);

  // Any pose: both transforms rigid and proper, the elbow joint carried by the shoulder only.
  const ArmPose pose{1.1, -0.4, 0.7};
  const auto G = bone_transforms(pose, o);
  for (const auto& g : G) {
    const Eigen::Matrix3d R = g.topLeftCorner<3, 3>();
    EXPECT_TRUE((R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    EXPECT_EQ(g.row(3), Eigen::RowVector4d(0, 0, 0, 1));
  }
  // Swinging about +y by σ takes (e, 0, 0) to (e cos σ, 0, -e sin σ).
  const double e = o.length / 2.0, sigma = pose.shoulder_angle_rad;
  const Eigen::Vector3d elbow_world(e * std::cos(sigma), 0, -e * std::sin(sigma));
  EXPECT_LT((G[kForearm].topRightCorner<3, 1>() - elbow_world).norm(), 1e-12);
  // The forearm's long axis (bone-local +x) after twisting about itself and flexing about z by θ
  // then swinging by σ: Ry(σ)·(cos θ, sin θ, 0).
  const double theta = pose.elbow_angle_rad;
  const Eigen::Vector3d axis(std::cos(theta) * std::cos(sigma), std::sin(theta),
                             -std::cos(theta) * std::sin(sigma));
  EXPECT_LT((G[kForearm].block<3, 1>(0, 0) - axis).norm(), 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Posing

TEST(BendingArmPose, RestPoseReproducesTheRestMeshExactly) {
  const ArmRig rig = make_arm_rig();
  const PointMatrix lbs = pose_linear_blend(ArmPose{}, rig);
  const PointMatrix expensive = pose_expensive(ArmPose{}, rig);
  ASSERT_EQ(lbs.rows(), rig.rest.V.rows());
  ASSERT_EQ(expensive.rows(), rig.rest.V.rows());
  EXPECT_TRUE((lbs.array() == rig.rest.V.array()).all());
  EXPECT_TRUE((expensive.array() == rig.rest.V.array()).all());
}

TEST(BendingArmPose, StraightArmSwungAtTheShoulderMovesRigidly) {
  const ArmRig rig = make_arm_rig();
  for (const double sigma : {0.3, -0.7, 2.0}) {
    SCOPED_TRACE(::testing::Message() << "shoulder " << sigma);
    const ArmPose pose{0.0, sigma, 0.0};
    const PointMatrix lbs = pose_linear_blend(pose, rig);
    const PointMatrix expensive = pose_expensive(pose, rig);
    // A rotation about +y: x' = x cos σ + z sin σ, z' = -x sin σ + z cos σ.
    for (Eigen::Index i = 0; i < rig.rest.V.rows(); ++i) {
      const Eigen::Vector3d v = point(rig.rest.V, i);
      const Eigen::Vector3d expected(v.x() * std::cos(sigma) + v.z() * std::sin(sigma), v.y(),
                                     -v.x() * std::sin(sigma) + v.z() * std::cos(sigma));
      ASSERT_LT((point(lbs, i) - expected).norm(), 1e-6) << "vertex " << i;
    }
    // Pairwise distances kept (a sample of pairs across the whole arm).
    for (Eigen::Index i = 0; i < rig.rest.V.rows(); i += 37) {
      for (Eigen::Index j = i + 1; j < rig.rest.V.rows(); j += 53) {
        EXPECT_NEAR((point(lbs, i) - point(lbs, j)).norm(),
                    (point(rig.rest.V, i) - point(rig.rest.V, j)).norm(), 2e-6);
      }
    }
    // No bend, no twist: nothing for the expensive rig to correct.
    EXPECT_LT(max_distance(expensive, lbs), 1e-6);
  }
}

TEST(BendingArmPose, LinearBlendRotatesTheForearmAboutTheElbow) {
  const ArmRig rig = make_arm_rig();
  const BendingArmOptions& o = rig.options;
  const double e = o.length / 2.0;
  const double theta = 1.1, tau = 0.4;
  const PointMatrix lbs = pose_linear_blend(ArmPose{theta, 0.0, tau}, rig);
  const PointMatrix expensive = pose_expensive(ArmPose{theta, 0.0, tau}, rig);
  int forearm = 0, upper = 0;
  for (Eigen::Index i = 0; i < rig.rest.V.rows(); ++i) {
    const Eigen::Vector3d v = point(rig.rest.V, i);
    if (v.x() > e + o.elbow_zone_width / 2.0) {
      // Twist about the forearm's axis (x), then flex about z through the elbow.
      const double y1 = v.y() * std::cos(tau) - v.z() * std::sin(tau);
      const double z1 = v.y() * std::sin(tau) + v.z() * std::cos(tau);
      const double dx = v.x() - e;
      const Eigen::Vector3d expected(e + dx * std::cos(theta) - y1 * std::sin(theta),
                                     dx * std::sin(theta) + y1 * std::cos(theta), z1);
      ASSERT_LT((point(lbs, i) - expected).norm(), 1e-6) << "forearm vertex " << i;
      // The biceps is on the upper arm: the forearm is rigid in the expensive rig too.
      ASSERT_LT((point(expensive, i) - expected).norm(), 1e-6) << "forearm vertex " << i;
      ++forearm;
    } else if (v.x() < e - o.elbow_zone_width / 2.0) {
      ASSERT_LT((point(lbs, i) - v).norm(), 1e-6) << "upper-arm vertex " << i;
      ++upper;
    }
  }
  EXPECT_GT(forearm, 10 * o.segments);
  EXPECT_GT(upper, 10 * o.segments);
}

// Biceps: with 41 rings, ring 11 lies at x = 2·11/40 = 0.55, the bump's centre.
TEST(BendingArmPose, BicepsBulgesOutwardAndGrowsMonotonicallyWithFlexion) {
  BendingArmOptions o;
  o.rings = 41;
  const ArmRig rig = make_arm_rig(o);
  const int centre_ring = 11;
  ASSERT_FLOAT_EQ(rig.rest.V(ring_vertex(o, centre_ring, 0), 0),
                  static_cast<float>(o.bulge_center_x));
  const Eigen::Index top = ring_vertex(o, centre_ring, 0);  // φ = 0: +y, flexor side
  const Eigen::Index bottom = ring_vertex(o, centre_ring, o.segments / 2);  // φ = π: extensor side

  double previous = -1.0;
  for (double degrees = 0.0; degrees <= 130.0; degrees += 5.0) {
    SCOPED_TRACE(::testing::Message() << degrees << " degrees");
    const ArmPose pose{degrees * kDeg, 0.0, 0.0};
    const PointMatrix lbs = pose_linear_blend(pose, rig);
    const PointMatrix expensive = pose_expensive(pose, rig);
    // The upper arm does not move (shoulder 0), so the outward normal at the top is +y.
    const Eigen::Vector3d bulge = point(expensive, top) - point(lbs, top);
    EXPECT_NEAR(bulge.x(), 0.0, 1e-7);
    EXPECT_NEAR(bulge.z(), 0.0, 1e-7);
    if (degrees == 0.0) {
      EXPECT_EQ(bulge.y(), 0.0);
    } else {
      EXPECT_GT(bulge.y(), previous) << "the bulge must grow with flexion";
    }
    EXPECT_LE(bulge.y(), o.bulge_amplitude + 1e-7);
    previous = bulge.y();
    // Nothing on the extensor side.
    EXPECT_LT((point(expensive, bottom) - point(lbs, bottom)).norm(), 1e-7);
  }
  EXPECT_GT(previous, 0.5 * o.bulge_amplitude);

  // At and beyond full flexion the bump's centre is raised by exactly the amplitude.
  for (const double theta : {o.bulge_full_flexion_rad, o.bulge_full_flexion_rad + 0.2}) {
    const ArmPose pose{theta, 0.0, 0.0};
    const double raised = pose_expensive(pose, rig)(top, 1) - pose_linear_blend(pose, rig)(top, 1);
    EXPECT_NEAR(raised, o.bulge_amplitude, 1e-6);
  }
  // Hyperextension relaxes the muscle: no bulge.
  const ArmPose extended{-0.3, 0.0, 0.0};
  EXPECT_LT(
      (point(pose_expensive(extended, rig), top) - point(pose_linear_blend(extended, rig), top))
          .norm(),
      1e-7);
}

TEST(BendingArmPose, BicepsActivationIsSmoothAtBothEnds) {
  const BendingArmOptions o;
  EXPECT_EQ(biceps_activation(0.0, o), 0.0);
  EXPECT_EQ(biceps_activation(-1.0, o), 0.0);
  EXPECT_EQ(biceps_activation(o.bulge_full_flexion_rad, o), 1.0);
  EXPECT_EQ(biceps_activation(o.bulge_full_flexion_rad + 1.0, o), 1.0);
  // C1 where it meets the constants: the one-sided slope vanishes like h² (a linear ramp, whose
  // slope is 1 / full flexion ≈ 0.4, would fail by four orders of magnitude).
  const double h = 1e-3;
  EXPECT_LT(biceps_activation(h, o) / h, 1e-4);
  EXPECT_LT((1.0 - biceps_activation(o.bulge_full_flexion_rad - h, o)) / h, 1e-4);
}

// With 49 rings, ring 24 lies at x = 1, the elbow, where both weights are 1/2.
TEST(BendingArmPose, ElbowKeepsItsCrossSectionWhereLinearBlendCollapses) {
  BendingArmOptions o;
  o.rings = 49;
  o.bulge_amplitude = 0.0;  // isolate the elbow correction
  const ArmRig rig = make_arm_rig(o);
  const int elbow_ring = 24;
  const Eigen::Vector3d elbow(o.length / 2.0, 0, 0);
  ASSERT_FLOAT_EQ(rig.rest.V(ring_vertex(o, elbow_ring, 0), 0), static_cast<float>(elbow.x()));

  // Bending by θ: SSD's half-and-half blend of I and Rz(θ) is cos(θ/2)·Rz(θ/2) in the bending
  // plane, so the flexor/extensor points (φ = 0, π) end up at r·cos(θ/2) from the elbow, while
  // the points on the bending axis (φ = ±π/2) stay at r. Twisting by τ: the blend of I and
  // Rx(τ) is cos(τ/2)·Rx(τ/2) across the whole section (the candy wrapper).
  struct Case {
    ArmPose pose;
    double collapse_at_top;  // SSD's distance from the elbow at φ = 0, over r
  };
  for (const Case c :
       {Case{{kPi / 2, 0, 0}, std::cos(kPi / 4)}, Case{{0, 0, 2.0 * kPi / 3}, 0.5}}) {
    SCOPED_TRACE(::testing::Message()
                 << "elbow " << c.pose.elbow_angle_rad << " twist " << c.pose.forearm_twist_rad);
    const PointMatrix lbs = pose_linear_blend(c.pose, rig);
    const PointMatrix expensive = pose_expensive(c.pose, rig);
    EXPECT_NEAR((point(lbs, ring_vertex(o, elbow_ring, 0)) - elbow).norm(),
                c.collapse_at_top * o.radius, 1e-6);
    for (int s = 0; s < o.segments; ++s) {
      EXPECT_NEAR((point(expensive, ring_vertex(o, elbow_ring, s)) - elbow).norm(), o.radius, 1e-6)
          << "segment " << s;
    }
  }

  // The enclosed volume: SSD loses some at a right-angle bend; the corrected rig much less.
  const double rest_volume = signed_volume(rig.rest.V, rig.rest.F);
  const ArmPose bent{kPi / 2, 0.0, 0.0};
  const double lbs_loss = rest_volume - signed_volume(pose_linear_blend(bent, rig), rig.rest.F);
  const double expensive_loss =
      std::abs(rest_volume - signed_volume(pose_expensive(bent, rig), rig.rest.F));
  EXPECT_GT(lbs_loss, 0.01 * rest_volume);
  EXPECT_LT(expensive_loss, 0.25 * lbs_loss);

  // A gain of zero turns the correction off.
  BendingArmOptions off = o;
  off.elbow_volume_gain = 0.0;
  const ArmRig plain = make_arm_rig(off);
  EXPECT_LT(max_distance(pose_expensive(bent, plain), pose_linear_blend(bent, plain)), 1e-7);
}

TEST(BendingArmPose, ExpensiveRigIsContinuousInEveryPoseParameter) {
  const ArmRig rig = make_arm_rig();
  // Sweep each parameter in small steps. Lipschitz bound: no point is farther than the wrist
  // cap's rim from a joint, so rotating by dα moves it by at most (length + radius)·dα, and the
  // corrections add less than that again; a jump anywhere along a sweep (a branch, a clamp with
  // a step, an atan2 seam) would exceed the bound.
  const double step = 4e-3;
  const double bound = 2.0 * (rig.options.length + rig.options.radius) * step;
  struct Sweep {
    const char* name;
    ArmPose start;
    double ArmPose::*parameter;
    double end;
  };
  for (const Sweep& sweep : {Sweep{"elbow", {-0.3, 0.3, -0.4}, &ArmPose::elbow_angle_rad, 2.9},
                             Sweep{"shoulder", {1.2, -kPi, 0.3}, &ArmPose::shoulder_angle_rad, kPi},
                             Sweep{"twist", {1.2, 0.2, -1.6}, &ArmPose::forearm_twist_rad, 1.6}}) {
    ArmPose pose = sweep.start;
    PointMatrix previous = pose_expensive(pose, rig);
    double largest = 0.0;
    while (pose.*sweep.parameter < sweep.end) {
      pose.*sweep.parameter += step;
      PointMatrix current = pose_expensive(pose, rig);
      largest = std::max(largest, max_distance(current, previous));
      previous = std::move(current);
    }
    EXPECT_LT(largest, bound) << sweep.name;
    EXPECT_GT(largest, 0.0) << sweep.name;
  }
}

TEST(BendingArmPose, ScalingEveryLengthScalesThePosedMesh) {
  const BendingArmOptions o;
  const ArmPose pose{1.9, 0.2, -0.3};
  const PointMatrix reference = pose_expensive(pose, make_arm_rig(o));
  for (const double s : {1e-4, 1e4}) {
    BendingArmOptions scaled = o;
    scaled.length *= s;
    scaled.radius *= s;
    scaled.elbow_zone_width *= s;
    scaled.bulge_amplitude *= s;
    scaled.bulge_center_x *= s;
    scaled.bulge_half_length *= s;
    const PointMatrix P = pose_expensive(pose, make_arm_rig(scaled));
    EXPECT_LT(max_distance(P / static_cast<float>(s), reference), 1e-5 * o.length) << "scale " << s;
  }
}

// ---------------------------------------------------------------------------------------------
// Animation

TEST(BendingArmAnimation, LoopsSmoothlyWithinItsRange) {
  const int frames = 120;
  const std::vector<ArmPose> poses = demo_animation(frames);
  ASSERT_EQ(poses.size(), static_cast<size_t>(frames));
  const auto as_vector = [](const ArmPose& p) {
    return Eigen::Vector3d(p.elbow_angle_rad, p.shoulder_angle_rad, p.forearm_twist_rad);
  };
  // Phase 0 is the rest pose; phase 1 is phase 0 again.
  EXPECT_EQ(as_vector(poses.front()), Eigen::Vector3d::Zero());
  EXPECT_LT((as_vector(demo_pose(1.0)) - as_vector(demo_pose(0.0))).norm(), 1e-12);
  // The elbow peaks at 130° half way round; the others stay within a small range.
  EXPECT_NEAR(poses[frames / 2].elbow_angle_rad, 130.0 * kDeg, 1e-12);
  double largest_step = 0.0;
  for (int f = 0; f < frames; ++f) {
    const ArmPose& p = poses[static_cast<size_t>(f)];
    EXPECT_GE(p.elbow_angle_rad, 0.0);
    EXPECT_LE(p.elbow_angle_rad, 130.0 * kDeg + 1e-12);
    EXPECT_LE(std::abs(p.shoulder_angle_rad), 15.0 * kDeg + 1e-12);
    EXPECT_LE(std::abs(p.forearm_twist_rad), 25.0 * kDeg + 1e-12);
    if (f > 0) {
      const ArmPose& before = poses[static_cast<size_t>(f - 1)];
      largest_step = std::max(largest_step, (as_vector(p) - as_vector(before)).norm());
    }
  }
  // Wrapping from the last frame to the first is a step like any other, not a jump.
  const double wrap = (as_vector(poses.front()) - as_vector(poses.back())).norm();
  EXPECT_GT(wrap, 0.0);
  EXPECT_LE(wrap, largest_step * 1.0001);
  // Deterministic, and frame f samples phase f / frames.
  const std::vector<ArmPose> again = demo_animation(frames);
  for (int f = 0; f < frames; ++f) {
    const auto i = static_cast<size_t>(f);
    EXPECT_EQ(as_vector(again[i]), as_vector(poses[i]));
    EXPECT_EQ(as_vector(poses[i]), as_vector(demo_pose(static_cast<double>(f) / frames)));
  }
}

// ---------------------------------------------------------------------------------------------
// Repository

TEST(DemoRepository, WritesAContainerThatReadsBackWithTheDocumentedSections) {
  const animspace::testing::TempDir dir;
  const Status written = write_demo_repository(dir.path());
  ASSERT_TRUE(written.ok()) << written.error().message;
  const std::filesystem::path file = dir.path() / "arm" / "1" / "model.anim";
  EXPECT_EQ(demo_model_path(dir.path()), file);
  EXPECT_EQ(kDemoModelName, "arm");
  ASSERT_TRUE(std::filesystem::is_regular_file(file));

  const Result<container::ModelContainer> model = container::read_file(file);
  ASSERT_TRUE(model.ok()) << model.error().message;
  EXPECT_EQ(model->metadata_value("kind"), "mesh_sequence");
  EXPECT_EQ(model->metadata_value("generator"), "animspace demo bending arm");
  EXPECT_EQ(model->metadata_value("up_axis"), "y");
  EXPECT_EQ(model->metadata_value("units"), "arbitrary (arm length 2)");
  EXPECT_FALSE(model->metadata_value("description").empty());

  const BendingArmOptions o;
  const Eigen::Index n = static_cast<Eigen::Index>(o.rings) * o.segments + 2;
  const Eigen::Index frames = kDemoFrames;
  ASSERT_EQ(frames, 120);

  const auto rest = model->points("mesh.rest_points");
  ASSERT_TRUE(rest.ok()) << rest.error().message;
  EXPECT_EQ(rest->rows(), n);
  const auto faces = model->faces("mesh.faces");
  ASSERT_TRUE(faces.ok()) << faces.error().message;
  EXPECT_EQ(faces->rows(), 2 * o.segments * o.rings);

  const auto parents = model->int_matrix("skeleton.parents", 1);
  ASSERT_TRUE(parents.ok()) << parents.error().message;
  ASSERT_EQ(parents->rows(), 2);
  EXPECT_EQ((*parents)(0, 0), -1);
  EXPECT_EQ((*parents)(1, 0), 0);

  const auto rest_transforms = model->double_matrix("skeleton.rest_transforms", 16);
  ASSERT_TRUE(rest_transforms.ok()) << rest_transforms.error().message;
  ASSERT_EQ(rest_transforms->rows(), 2);
  // Row-major 4×4: the forearm's translation (elbow at x = 1) is element (0, 3) = index 3.
  EXPECT_EQ((*rest_transforms)(1, 3), 1.0);
  EXPECT_EQ((*rest_transforms)(1, 12), 0.0);
  EXPECT_EQ((*rest_transforms)(1, 15), 1.0);

  const auto weights = model->float_matrix("skinning.weights", 2);
  ASSERT_TRUE(weights.ok()) << weights.error().message;
  ASSERT_EQ(weights->rows(), n);
  for (Eigen::Index i = 0; i < n; ++i) EXPECT_NEAR(weights->row(i).sum(), 1.0f, 1e-6f);

  const auto sequence = model->float_matrix("sequence.frames", static_cast<int>(3 * n));
  ASSERT_TRUE(sequence.ok()) << sequence.error().message;
  ASSERT_EQ(sequence->rows(), frames);
  // Frame 0 is the rest pose, x0 y0 z0 x1 … .
  for (Eigen::Index i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ((*sequence)(0, 3 * i + c), (*rest)(i, c));
  }
  // Half way, the elbow is bent by 130°: the wrist cap's centre is at e + (cos 130°, sin 130°)·e
  // for e = 1 (shoulder swing sin π = 0 to rounding; the twist keeps the axis).
  const Eigen::Index wrist = n - 1;
  const double theta = 130.0 * kDeg;
  EXPECT_NEAR((*sequence)(frames / 2, 3 * wrist + 0), 1.0 + std::cos(theta), 1e-5);
  EXPECT_NEAR((*sequence)(frames / 2, 3 * wrist + 1), std::sin(theta), 1e-5);

  const auto bones = model->double_matrix("sequence.bone_transforms", 32);
  ASSERT_TRUE(bones.ok()) << bones.error().message;
  EXPECT_EQ(bones->rows(), frames);
  const auto parameters = model->double_matrix("sequence.pose_parameters", 3);
  ASSERT_TRUE(parameters.ok()) << parameters.error().message;
  ASSERT_EQ(parameters->rows(), frames);
  EXPECT_NEAR((*parameters)(frames / 2, 0), theta, 1e-12);
  // The forearm's bone-to-world rotation in frame f has first column Ry(σ)·(cos θ, sin θ, 0).
  for (Eigen::Index f = 0; f < frames; f += 17) {
    const double elbow = (*parameters)(f, 0), sigma = (*parameters)(f, 1);
    EXPECT_NEAR((*bones)(f, 16 + 0), std::cos(elbow) * std::cos(sigma), 1e-12);
    EXPECT_NEAR((*bones)(f, 16 + 4), std::sin(elbow), 1e-12);
    EXPECT_NEAR((*bones)(f, 16 + 8), -std::cos(elbow) * std::sin(sigma), 1e-12);
    EXPECT_EQ((*bones)(f, 15), 1.0);
  }

  // Writing again replaces the file in place.
  const Status rewritten = write_demo_repository(dir.path());
  EXPECT_TRUE(rewritten.ok()) << rewritten.error().message;
}

TEST(DemoRepository, NamesThePathWhenTheDirectoryCannotBeCreated) {
  const animspace::testing::TempDir dir;
  const std::filesystem::path blocker = dir.path() / "not-a-directory";
  animspace::testing::write_text_file(blocker, "a file where the repository should be");
  const Status written = write_demo_repository(blocker);
  ASSERT_FALSE(written.ok());
  EXPECT_EQ(written.error().code, ErrorCode::kIo);
  EXPECT_NE(written.error().message.find(blocker.string()), std::string::npos)
      << written.error().message;
}

}  // namespace
}  // namespace animspace::demo
