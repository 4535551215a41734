// Small generated skeletons, poses and models for the animation-space tests (no shared data).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

#include <Eigen/Geometry>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"

namespace animspace::testing {

// A uniformly distributed rotation (Haar measure): a normalised Gaussian quaternion.
inline Eigen::Matrix3d random_rotation(std::mt19937_64& engine) {
  std::normal_distribution<double> normal;
  Eigen::Quaterniond q(normal(engine), normal(engine), normal(engine), normal(engine));
  q.normalize();
  return q.toRotationMatrix();
}

// A rotation by an angle drawn uniformly from [-max_angle, max_angle] about a random axis.
inline Eigen::Matrix3d random_bounded_rotation(std::mt19937_64& engine, double max_angle) {
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> angle(-max_angle, max_angle);
  const Eigen::Vector3d axis = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
  return Eigen::AngleAxisd(angle(engine), axis).toRotationMatrix();
}

// A chain-and-branch skeleton of `bones` bones (bone 0 the fixed root at the origin). Bone j's
// parent is drawn from 0 … j-1 and its joint sits `bone_length` from the parent's joint in a
// random direction; rest rotations are the identity (Ĝ_j a pure translation).
inline animation_space::Skeleton random_skeleton(int bones, uint64_t seed, double bone_length = 1.0) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  animation_space::Skeleton skeleton;
  skeleton.parents.push_back(-1);
  skeleton.rest.push_back(animation_space::Transform::Identity());
  for (int j = 1; j < bones; ++j) {
    const int parent = std::uniform_int_distribution<int>(0, j - 1)(engine);
    const Eigen::Vector3d direction = Eigen::Vector3d(normal(engine), normal(engine), normal(engine)).normalized();
    const Eigen::Vector3d joint =
        skeleton.rest[static_cast<size_t>(parent)].topRightCorner<3, 1>() + bone_length * direction;
    skeleton.parents.push_back(parent);
    skeleton.rest.push_back(animation_space::make_transform(Eigen::Matrix3d::Identity(), joint));
  }
  return skeleton;
}

// A pose: every non-root joint rotated from its rest joint transform by a random rotation of
// at most `max_angle` (π gives any rotation), translations fixed (the "rotations and fixed
// translations" model of Merry 2007 §3.3.1). Returns the global transforms G_j.
inline animation_space::TransformList random_pose(const animation_space::Skeleton& skeleton, std::mt19937_64& engine,
                                                  double max_angle) {
  animation_space::TransformList joints = animation_space::rest_joint_transforms(skeleton);
  for (size_t j = 1; j < joints.size(); ++j) {
    joints[j].topLeftCorner<3, 3>() = joints[j].topLeftCorner<3, 3>() * random_bounded_rotation(engine, max_angle);
  }
  return animation_space::global_transforms(skeleton, joints);
}

// A model of `vertices` vertices with 1–3 random influences each and random 4-vectors whose
// weights sum to 1 (a general animation-space model, not an SSD one).
inline animation_space::AnimationSpaceModel random_model(const animation_space::Skeleton& skeleton, int vertices,
                                                         uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  animation_space::AnimationSpaceModel model;
  model.skeleton = skeleton;
  const int b = skeleton.bone_count();
  std::vector<Eigen::Vector4d> columns;
  for (int i = 0; i < vertices; ++i) {
    std::vector<int32_t> bones;
    const int count = std::min(b, std::uniform_int_distribution<int>(1, 3)(engine));
    while (static_cast<int>(bones.size()) < count) {
      const int bone = std::uniform_int_distribution<int>(0, b - 1)(engine);
      if (std::find(bones.begin(), bones.end(), bone) == bones.end()) bones.push_back(bone);
    }
    std::sort(bones.begin(), bones.end());
    double weight_sum = 0;
    for (size_t k = 0; k < bones.size(); ++k) {
      Eigen::Vector4d p(normal(engine), normal(engine), normal(engine), 0.2 + std::abs(normal(engine)));
      weight_sum += p(3);
      columns.push_back(p);
      model.influences.bones.push_back(bones[k]);
    }
    for (size_t k = columns.size() - bones.size(); k < columns.size(); ++k) columns[k](3) /= weight_sum;
    model.influences.offsets.push_back(static_cast<int32_t>(model.influences.bones.size()));
  }
  model.positions.resize(4, static_cast<Eigen::Index>(columns.size()));
  for (size_t k = 0; k < columns.size(); ++k) model.positions.col(static_cast<Eigen::Index>(k)) = columns[k];
  return model;
}

}  // namespace animspace::testing
