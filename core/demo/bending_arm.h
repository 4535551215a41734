// The bundled demo: a bending arm built from code, with an "expensive rig" to learn from.
//
// Merry 2007 uses a bent cylinder as its running example of the artefacts of skeletal subspace
// deformation (SSD, linear blend skinning): the collapsing elbow and the candy wrapper (§2.2.2,
// Figures 2.2 and 8.5), and an arm whose upper-arm muscle "bulges depending on the angle of the
// elbow joint" as its hardest fitting example (§8.2, Figure 8.4). This module builds both from
// nothing but code:
//   - a capped cylinder (`make_arm_mesh`) with two bones, upper arm and forearm (`make_arm_rig`);
//   - plain SSD, v = Σ_j w_j G_j Ĝ_j⁻¹ v̂ (eq. 2.2; `pose_linear_blend`);
//   - an expensive rig (`pose_expensive`): SSD plus the non-linear corrections a production rig
//     would have — a biceps bulge growing with elbow flexion and an elbow (and wrist twist) that
//     keeps its cross-section instead of collapsing. PMSC (seed 000) treats it as the full
//     calculation to accelerate; animation-space fitting (§4.1) approximates it from example
//     poses, which plain SSD cannot do (the bulge and the restored cross-section are not linear
//     in the bone transforms).
//
// Frames and units: lengths are in arbitrary units (the default arm is 2 long). The arm lies
// along +x from the shoulder at the origin to the wrist at x = length; the elbow is at
// x = length / 2. +y is up and is also the flexor side: flexing the elbow brings the forearm
// towards +y, and the biceps sits on the +y side of the upper arm. +z completes a right-handed
// frame. Angles are in radians, rotations right-handed.
//
// Precision: everything is computed in double and rounded to float32 points at the end, so the
// rest pose is reproduced bit for bit and the posed points are accurate to float rounding.
#pragma once

#include <array>
#include <cstdint>
#include <numbers>
#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"

namespace animspace::demo {

inline constexpr int kArmBones = 2;
inline constexpr int kUpperArm = 0;  // the root; its joint is the shoulder, at the origin
inline constexpr int kForearm = 1;   // child of the upper arm; its joint is the elbow
// Parent of each bone, -1 for the root (Merry 2007 §2.1 labels the root bone 0).
inline constexpr std::array<int32_t, kArmBones> kArmParents = {-1, kUpperArm};

// Shape of the arm and of its rig. All lengths share the arm's units; scaling every length
// field by s scales every posed point by s.
struct BendingArmOptions {
  // Rings of vertices along the arm, evenly spaced from the shoulder (x = 0) to the wrist
  // (x = length), both end rings included; >= 2. An odd count puts a ring exactly at the elbow.
  int rings = 48;
  // Vertices around each ring; >= 3. The side is the prism over this inscribed polygon.
  int segments = 24;
  double length = 2.0;   // shoulder to wrist; > 0
  double radius = 0.18;  // of the cylinder; > 0

  // Skinning: the forearm weight rises from 0 to 1 across [length/2 - w/2, length/2 + w/2]
  // with w = elbow_zone_width (a C2 smootherstep, symmetric about the elbow); 0 < w < length.
  double elbow_zone_width = 0.4;

  // Expensive rig, biceps: a bump on the upper arm's flexor (+y) side, centred on the line
  // y > 0, z = 0 at x = bulge_center_x, extending bulge_half_length either way along the arm
  // and bulge_half_angle_rad either way around it (0 < half angle <= π). It displaces the skin
  // along the outward normal by at most bulge_amplitude, reached at elbow flexion
  // bulge_full_flexion_rad (the anatomical limit, ~145°) and zero when the arm is straight or
  // hyperextended.
  double bulge_amplitude = 0.05;
  double bulge_center_x = 0.55;
  double bulge_half_length = 0.3;
  double bulge_half_angle_rad = 1.2;
  double bulge_full_flexion_rad = 145.0 * std::numbers::pi / 180.0;

  // Expensive rig, elbow: the fraction of SSD's cross-section collapse that is restored in the
  // elbow zone (1 = cross-sections keep their rest shape, 0 = plain SSD).
  double elbow_volume_gain = 1.0;
};

// A pose of the arm; all zero is the rest pose (straight arm along +x). Parameters must be
// finite (asserted: poses are made by code; a server validates client input before this).
struct ArmPose {
  // Flexion: rotation of the forearm about the upper arm's +z axis through the elbow. Positive
  // bends the forearm towards the upper arm's +y (flexor) side; 0 is straight, negative is
  // hyperextension. The rig is designed for [0, bulge_full_flexion_rad].
  double elbow_angle_rad = 0.0;
  // Rotation of the whole arm about the world +y (up) axis through the shoulder: a horizontal
  // swing; positive turns the wrist from +x towards -z.
  double shoulder_angle_rad = 0.0;
  // Rotation of the forearm about its own long axis (its local +x), applied before flexion:
  // pronation/supination. Large values show SSD's candy-wrapper collapse (Merry 2007 Fig. 2.2c).
  double forearm_twist_rad = 0.0;
};

// A closed, manifold triangle mesh of the capped cylinder, faces counter-clockwise seen from
// outside. V is rings·segments + 2 by 3: ring k (x = length·k/(rings-1)) holds vertices
// k·segments + s at angle φ_s = 2π s / segments from +y towards +z, (x, r cos φ_s, r sin φ_s);
// then the shoulder cap centre (0,0,0) and the wrist cap centre (length,0,0). F is
// 2·segments·rings by 3: two triangles per side quad, one fan triangle per cap edge.
TriangleMesh make_arm_mesh(const BendingArmOptions& options);

// Ĝ_j, bone to world in the rest pose: the upper arm's frame is the world frame; the
// forearm's is translated to the elbow (length/2, 0, 0). Both are rigid.
std::array<Eigen::Matrix4d, kArmBones> rest_bone_transforms(const BendingArmOptions& options);

// #V by 2 linear-blend-skinning weights for rest points V (#V by 3): column kForearm is the
// smootherstep of x across the elbow zone, column kUpperArm is 1 minus it. Entries lie in
// [0, 1], rows sum to 1, and vertices outside the zone have weight exactly 1 on their bone.
Eigen::MatrixXd arm_skinning_weights(const PointMatrix& V, const BendingArmOptions& options);

// G_j, world from bone, for a pose: G_upper = Ry(shoulder), G_fore = G_upper · T(elbow) ·
// Rz(elbow angle) · Rx(twist). At the rest pose G_j = Ĝ_j.
std::array<Eigen::Matrix4d, kArmBones> bone_transforms(const ArmPose& pose,
                                                       const BendingArmOptions& options);

// Everything posing needs, computed once (the struct a server caches).
struct ArmRig {
  BendingArmOptions options;
  TriangleMesh rest;                                       // V̂ (#V by 3) and F (#F by 3)
  std::array<Eigen::Matrix4d, kArmBones> rest_transforms;  // Ĝ_j
  Eigen::MatrixXd W;                                       // #V by 2 skinning weights
  // #V by 3: each rest vertex's offset from the bone axis, (0, y, z); zero on the cap centres.
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> radial;
  // #V: the biceps bump's spatial profile in [0, 1] (1 at the bump's centre, 0 outside it).
  Eigen::VectorXd bulge_profile;
};

// Builds the mesh, rest transforms, weights and the expensive rig's per-vertex data.
ArmRig make_arm_rig(const BendingArmOptions& options = {});

// Plain SSD (Merry 2007 eq. 2.2) of the rig's rest mesh: #V by 3.
PointMatrix pose_linear_blend(const ArmPose& pose, const ArmRig& rig);

// The expensive rig: SSD plus two corrections (#V by 3). With R = Ry(shoulder) the upper arm's
// rotation, Q(s) = Rz(s·elbow)·Rx(s·twist) the elbow's relative rotation taken a fraction s of
// the way, u a vertex's rest offset from the bone axis, n = u/|u| its rest normal and w its
// forearm weight:
//   elbow:  Δ = gain · R · [(Q(w) - I) - w (Q(1) - I)] u. With gain 1 the vertex becomes the SSD
//           image of its axis point plus R·Q(w)·u: each cross-section is carried rigidly by the
//           joint rotation interpolated at its weight (the non-linear blending of §2.3.3) rather
//           than by SSD's blended matrix, whose shrinkage is the collapsing elbow and the candy
//           wrapper (§2.2.2). Zero wherever w is 0 or 1 and whenever Q = I.
//   biceps: Δ = amplitude · f(elbow) · profile · R·Q(w)·n, with f the C2 smootherstep of
//           elbow / bulge_full_flexion_rad clamped to [0, 1].
// Both are smooth (C2) in the pose parameters and exactly zero at the rest pose (where the
// result equals the rest mesh bit for bit) and at any pose with elbow = twist = 0.
PointMatrix pose_expensive(const ArmPose& pose, const ArmRig& rig);

// f above: 0 for elbow <= 0, 1 for elbow >= bulge_full_flexion_rad, strictly increasing and
// C2 in between.
double biceps_activation(double elbow_angle_rad, const BendingArmOptions& options);

// The demo animation's range: the elbow flexes 0 → kDemoElbowMaxRad → 0, the shoulder swings
// ±kDemoShoulderSwingRad, the forearm twists ±kDemoTwistRad (twice per loop).
inline constexpr double kDemoElbowMaxRad = 130.0 * std::numbers::pi / 180.0;
inline constexpr double kDemoShoulderSwingRad = 15.0 * std::numbers::pi / 180.0;
inline constexpr double kDemoTwistRad = 25.0 * std::numbers::pi / 180.0;

// The demo pose at `phase` (any real number; period 1, phase 0 is the rest pose). Every
// parameter is a trigonometric polynomial of the phase, so the animation is smooth and loops
// without a jump.
ArmPose demo_pose(double phase);

// `frames` (>= 1) poses sampled at phases f / frames, f = 0 … frames-1: one loop, so the frame
// after the last is the first again. Deterministic.
std::vector<ArmPose> demo_animation(int frames);

}  // namespace animspace::demo
