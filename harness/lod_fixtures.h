// Small models for the level-of-detail tests: the demo's bending arm as an animation-space model
// (a real elbow whose detail matters only when bent), a flat sheet and a pyramid whose collapse
// costs can be worked by hand.
#pragma once

#include <vector>

#include "core/animspace/import.h"
#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/demo/bending_arm.h"

namespace animspace::testing {

struct LodCase {
  animation_space::AnimationSpaceModel model;
  animation_space::AnimationSpaceMetrics metrics;
  std::vector<animation_space::TransformList> poses;  // the poses P was averaged over
};

// The bending arm (rings × segments + 2 vertices) skinned with its SSD weights, converted to
// animation space (§3.1), with P averaged over `frames` poses of the demo animation.
inline LodCase arm_lod_case(int rings = 13, int segments = 8, int frames = 24) {
  demo::BendingArmOptions options;
  options.rings = rings;
  options.segments = segments;
  const demo::ArmRig rig = demo::make_arm_rig(options);
  animation_space::LinearBlendModel lbs;
  lbs.skeleton.parents = {-1, 0, 1};
  lbs.skeleton.rest = {animation_space::Transform::Identity(), rig.rest_transforms[demo::kUpperArm],
                       rig.rest_transforms[demo::kForearm]};
  lbs.faces = rig.rest.F;
  lbs.rest_points = rig.rest.V.cast<double>().transpose();
  std::vector<double> weights;
  for (Eigen::Index v = 0; v < rig.rest.V.rows(); ++v) {
    for (int j = 0; j < 2; ++j) {
      const double w = rig.W(v, j == 0 ? demo::kUpperArm : demo::kForearm);
      if (w == 0) continue;
      lbs.influences.bones.push_back(j + 1);
      weights.push_back(w);
    }
    lbs.influences.offsets.push_back(static_cast<int32_t>(lbs.influences.bones.size()));
  }
  lbs.weights = Eigen::Map<const Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  LodCase c;
  c.model = animation_space::from_linear_blend(lbs);
  for (const demo::ArmPose& pose : demo::demo_animation(frames)) {
    const auto G = demo::bone_transforms(pose, rig.options);
    c.poses.push_back({animation_space::Transform::Identity(), G[demo::kUpperArm], G[demo::kForearm]});
  }
  c.metrics = animation_space::metrics_from_poses(c.model.skeleton, c.poses).value();
  return c;
}

// A rigid one-bone model (bone 0 only, so every pose is G = I and P = I: the L2,2 norm is the
// Euclidean one) with the given points and faces.
inline LodCase rigid_case(const Eigen::Matrix<double, Eigen::Dynamic, 3>& points, const FaceMatrix& faces) {
  LodCase c;
  c.model.skeleton.parents = {-1};
  c.model.skeleton.rest = {animation_space::Transform::Identity()};
  c.model.faces = faces;
  c.model.positions.resize(4, points.rows());
  for (Eigen::Index v = 0; v < points.rows(); ++v) {
    c.model.positions.col(v) << points.row(v).transpose(), 1.0;
    c.model.influences.bones.push_back(0);
    c.model.influences.offsets.push_back(static_cast<int32_t>(v + 1));
  }
  c.poses = {{animation_space::Transform::Identity()}};
  c.metrics = animation_space::metrics_from_poses(c.model.skeleton, c.poses).value();
  return c;
}

// An n × n grid of unit squares in the plane z = 0, two triangles each.
inline LodCase flat_sheet_case(int n) {
  Eigen::Matrix<double, Eigen::Dynamic, 3> points((n + 1) * (n + 1), 3);
  for (int i = 0; i <= n; ++i) {
    for (int j = 0; j <= n; ++j) points.row(i * (n + 1) + j) << j, i, 0;
  }
  FaceMatrix faces(2 * n * n, 3);
  int f = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const int a = i * (n + 1) + j, b = a + 1, c = a + n + 1, d = c + 1;
      faces.row(f++) << a, b, d;
      faces.row(f++) << a, d, c;
    }
  }
  return rigid_case(points, faces);
}

// An open square pyramid: apex (0, 0, h) over the ring (1,0,0), (0,1,0), (−1,0,0), (0,−1,0).
inline LodCase pyramid_case(double h) {
  Eigen::Matrix<double, Eigen::Dynamic, 3> points(5, 3);
  points << 0, 0, h, 1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1, 0;
  FaceMatrix faces(4, 3);
  faces << 0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1;
  return rigid_case(points, faces);
}

}  // namespace animspace::testing
