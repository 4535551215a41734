// The bending-arm demo: Merry 2007's bent cylinder (§2.2.2, §8.2) built procedurally, posed by
// SSD (eq. 2.2) and by an "expensive rig" with a biceps bulge and a volume-keeping elbow.
#include "core/demo/bending_arm.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace animspace::demo {
namespace {

using Matrix3d = Eigen::Matrix3d;
using Matrix4d = Eigen::Matrix4d;
using Vector3d = Eigen::Vector3d;

// Explicit rotations rather than Eigen::AngleAxis so that a zero angle gives the identity bit
// for bit (cos 0 = 1, sin 0 = 0), which the exact rest-pose guarantee relies on.
Matrix3d rotation_x(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Matrix3d r;
  r << 1, 0, 0,  //
      0, c, -s,  //
      0, s, c;
  return r;
}

Matrix3d rotation_y(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Matrix3d r;
  r << c, 0, s,  //
      0, 1, 0,   //
      -s, 0, c;
  return r;
}

Matrix3d rotation_z(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Matrix3d r;
  r << c, -s, 0,  //
      s, c, 0,    //
      0, 0, 1;
  return r;
}

Matrix4d homogeneous(const Matrix3d& linear, const Vector3d& translation) {
  Matrix4d m = Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = linear;
  m.topRightCorner<3, 1>() = translation;
  return m;
}

// Inverse of a rigid transform, [Rᵀ | -Rᵀt]: exact for the rest transforms (a pure translation
// inverts to its negation), unlike a general 4×4 inverse.
Matrix4d rigid_inverse(const Matrix4d& m) {
  const Matrix3d rt = m.topLeftCorner<3, 3>().transpose();
  return homogeneous(rt, -rt * m.topRightCorner<3, 1>());
}

// 6t⁵ - 15t⁴ + 10t³ on [0, 1], clamped outside: C2, with zero first and second derivatives at
// both ends, so weights and activations have no visible crease in shading.
double smootherstep(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

// (1 - t²)³ on |t| < 1, 0 outside: a C2 bump of height 1 with compact support.
double bump(double t) {
  const double a = 1.0 - t * t;
  return a > 0.0 ? a * a * a : 0.0;
}

void check_options(const BendingArmOptions& o) {
  assert(o.rings >= 2 && o.segments >= 3);
  assert(o.length > 0.0 && o.radius > 0.0);
  assert(o.elbow_zone_width > 0.0 && o.elbow_zone_width < o.length);
  assert(o.bulge_half_length > 0.0);
  assert(o.bulge_half_angle_rad > 0.0 && o.bulge_half_angle_rad <= std::numbers::pi);
  assert(o.bulge_full_flexion_rad > 0.0);
  static_cast<void>(o);
}

// Per-pose quantities shared by SSD and the expensive rig.
struct PoseFrame {
  std::array<Matrix4d, kArmBones> skinning;  // G_j Ĝ_j⁻¹
  Matrix3d upper_rotation;                   // R = Ry(shoulder)
};

PoseFrame pose_frame(const ArmPose& pose, const ArmRig& rig) {
  assert(std::isfinite(pose.elbow_angle_rad) && std::isfinite(pose.shoulder_angle_rad) &&
         std::isfinite(pose.forearm_twist_rad));
  const auto G = bone_transforms(pose, rig.options);
  PoseFrame frame;
  for (int j = 0; j < kArmBones; ++j) {
    const auto b = static_cast<size_t>(j);
    frame.skinning[b] = G[b] * rigid_inverse(rig.rest_transforms[b]);
  }
  frame.upper_rotation = G[kUpperArm].topLeftCorner<3, 3>();
  return frame;
}

// Eq. 2.2 for vertex i, in double.
Vector3d linear_blend(const PoseFrame& frame, const ArmRig& rig, Eigen::Index i) {
  const Vector3d rest = rig.rest.V.row(i).cast<double>().transpose();
  Vector3d v = Vector3d::Zero();
  for (int j = 0; j < kArmBones; ++j) {
    const Matrix4d& m = frame.skinning[static_cast<size_t>(j)];
    v += rig.W(i, j) * (m.topLeftCorner<3, 3>() * rest + m.topRightCorner<3, 1>());
  }
  return v;
}

}  // namespace

TriangleMesh make_arm_mesh(const BendingArmOptions& options) {
  check_options(options);
  const int rings = options.rings;
  const int segments = options.segments;
  const int ring_vertices = rings * segments;
  const int32_t shoulder_centre = ring_vertices;
  const int32_t wrist_centre = ring_vertices + 1;

  TriangleMesh mesh;
  mesh.V.resize(ring_vertices + 2, 3);
  for (int k = 0; k < rings; ++k) {
    // Computed as length·k/(rings-1) so that the last ring lands exactly on the wrist.
    const double x = options.length * k / (rings - 1);
    for (int s = 0; s < segments; ++s) {
      const double phi = 2.0 * std::numbers::pi * s / segments;
      mesh.V.row(k * segments + s) << static_cast<float>(x),
          static_cast<float>(options.radius * std::cos(phi)),
          static_cast<float>(options.radius * std::sin(phi));
    }
  }
  mesh.V.row(shoulder_centre) << 0.0f, 0.0f, 0.0f;
  mesh.V.row(wrist_centre) << static_cast<float>(options.length), 0.0f, 0.0f;

  // φ grows from +y towards +z, so along a ring t_φ × t_x points outwards: side triangles list
  // (k,s), (k,s+1), (k+1,s+1) and (k,s), (k+1,s+1), (k+1,s); the shoulder cap (normal -x) runs
  // against φ, the wrist cap (normal +x) with it.
  mesh.F.resize(2 * segments * rings, 3);
  int f = 0;
  const auto index = [segments](int k, int s) {
    return static_cast<int32_t>(k * segments + s % segments);
  };
  for (int k = 0; k + 1 < rings; ++k) {
    for (int s = 0; s < segments; ++s) {
      mesh.F.row(f++) << index(k, s), index(k, s + 1), index(k + 1, s + 1);
      mesh.F.row(f++) << index(k, s), index(k + 1, s + 1), index(k + 1, s);
    }
  }
  for (int s = 0; s < segments; ++s) {
    mesh.F.row(f++) << shoulder_centre, index(0, s + 1), index(0, s);
    mesh.F.row(f++) << wrist_centre, index(rings - 1, s), index(rings - 1, s + 1);
  }
  assert(f == mesh.F.rows());
  return mesh;
}

std::array<Eigen::Matrix4d, kArmBones> rest_bone_transforms(const BendingArmOptions& options) {
  return {Matrix4d::Identity(),
          homogeneous(Matrix3d::Identity(), Vector3d(options.length / 2.0, 0.0, 0.0))};
}

Eigen::MatrixXd arm_skinning_weights(const PointMatrix& V, const BendingArmOptions& options) {
  check_options(options);
  const double zone_start = options.length / 2.0 - options.elbow_zone_width / 2.0;
  Eigen::MatrixXd W(V.rows(), kArmBones);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const double forearm = smootherstep((V(i, 0) - zone_start) / options.elbow_zone_width);
    W(i, kForearm) = forearm;
    W(i, kUpperArm) = 1.0 - forearm;
  }
  return W;
}

std::array<Eigen::Matrix4d, kArmBones> bone_transforms(const ArmPose& pose,
                                                       const BendingArmOptions& options) {
  const Matrix4d upper = homogeneous(rotation_y(pose.shoulder_angle_rad), Vector3d::Zero());
  // Twist first (about the forearm's own axis), then flexion about the elbow, then the
  // shoulder: G_fore = G_upper · (Ĝ_upper⁻¹ Ĝ_fore) · local rotation.
  const Matrix4d local = homogeneous(
      rotation_z(pose.elbow_angle_rad) * rotation_x(pose.forearm_twist_rad), Vector3d::Zero());
  const Matrix4d elbow =
      homogeneous(Matrix3d::Identity(), Vector3d(options.length / 2.0, 0.0, 0.0));
  return {upper, upper * elbow * local};
}

ArmRig make_arm_rig(const BendingArmOptions& options) {
  check_options(options);
  ArmRig rig;
  rig.options = options;
  rig.rest = make_arm_mesh(options);
  rig.rest_transforms = rest_bone_transforms(options);
  rig.W = arm_skinning_weights(rig.rest.V, options);

  const Eigen::Index n = rig.rest.V.rows();
  rig.radial.resize(n, 3);
  rig.bulge_profile.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double x = rig.rest.V(i, 0), y = rig.rest.V(i, 1), z = rig.rest.V(i, 2);
    rig.radial.row(i) << 0.0, y, z;
    // The angle from the flexor line (+y) is undefined on the axis (the cap centres): give them
    // none; they lie outside the bump's support along x anyway.
    const bool on_axis = y == 0.0 && z == 0.0;
    const double around = on_axis ? options.bulge_half_angle_rad : std::atan2(z, y);
    rig.bulge_profile(i) = bump((x - options.bulge_center_x) / options.bulge_half_length) *
                           bump(around / options.bulge_half_angle_rad);
  }
  return rig;
}

PointMatrix pose_linear_blend(const ArmPose& pose, const ArmRig& rig) {
  const PoseFrame frame = pose_frame(pose, rig);
  PointMatrix P(rig.rest.V.rows(), 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    P.row(i) = linear_blend(frame, rig, i).cast<float>().transpose();
  }
  return P;
}

double biceps_activation(double elbow_angle_rad, const BendingArmOptions& options) {
  return smootherstep(elbow_angle_rad / options.bulge_full_flexion_rad);
}

PointMatrix pose_expensive(const ArmPose& pose, const ArmRig& rig) {
  const BendingArmOptions& o = rig.options;
  const PoseFrame frame = pose_frame(pose, rig);
  const Matrix3d& R = frame.upper_rotation;
  const auto elbow_relative = [&pose](double s) {
    return Matrix3d(rotation_z(s * pose.elbow_angle_rad) * rotation_x(s * pose.forearm_twist_rad));
  };
  const Matrix3d full_minus_identity = elbow_relative(1.0) - Matrix3d::Identity();
  const double bulge = o.bulge_amplitude * biceps_activation(pose.elbow_angle_rad, o);

  PointMatrix P(rig.rest.V.rows(), 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    Vector3d v = linear_blend(frame, rig, i);
    const double w = rig.W(i, kForearm);
    const Vector3d u = rig.radial.row(i).transpose();
    // R·Q(w) is the joint rotation interpolated at the vertex's weight; outside the elbow zone
    // (w = 0 or 1) it is the vertex's own bone rotation and the elbow term is exactly zero.
    // Written with Q - I rather than Q so that it is also exactly zero whenever Q = I (the rest
    // pose, or elbow = twist = 0), instead of a rounding residue of (1 - w) + w - 1.
    const Matrix3d Q = elbow_relative(w);
    v += o.elbow_volume_gain * (R * ((Q - Matrix3d::Identity()) - w * full_minus_identity) * u);
    const double r = u.norm();
    if (r > 0.0) v += (bulge * rig.bulge_profile(i) / r) * (R * Q * u);
    P.row(i) = v.cast<float>().transpose();
  }
  return P;
}

ArmPose demo_pose(double phase) {
  const double angle = 2.0 * std::numbers::pi * phase;
  ArmPose pose;
  pose.elbow_angle_rad = kDemoElbowMaxRad * 0.5 * (1.0 - std::cos(angle));
  pose.shoulder_angle_rad = kDemoShoulderSwingRad * std::sin(angle);
  pose.forearm_twist_rad = kDemoTwistRad * std::sin(2.0 * angle);
  return pose;
}

std::vector<ArmPose> demo_animation(int frames) {
  assert(frames >= 1);
  std::vector<ArmPose> poses;
  poses.reserve(static_cast<size_t>(std::max(frames, 0)));
  for (int f = 0; f < frames; ++f) poses.push_back(demo_pose(static_cast<double>(f) / frames));
  return poses;
}

}  // namespace animspace::demo
