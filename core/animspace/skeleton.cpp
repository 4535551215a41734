#include "core/animspace/skeleton.h"

#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <Eigen/LU>

namespace animspace::animation_space {
namespace {

bool is_affine(const Transform& m) {
  return m.allFinite() && m(3, 0) == 0.0 && m(3, 1) == 0.0 && m(3, 2) == 0.0 && m(3, 3) == 1.0;
}

}  // namespace

Status validate(const Skeleton& skeleton) {
  const int b = skeleton.bone_count();
  if (b == 0) return make_error(ErrorCode::kInvalidArgument, "skeleton has no bones; expected at least the root");
  if (static_cast<int>(skeleton.rest.size()) != b) {
    return make_error(ErrorCode::kInvalidArgument, "skeleton has " + std::to_string(b) + " parents but " +
                                                       std::to_string(skeleton.rest.size()) + " rest transforms");
  }
  if (!skeleton.names.empty() && static_cast<int>(skeleton.names.size()) != b) {
    return make_error(ErrorCode::kInvalidArgument, "skeleton has " + std::to_string(b) + " bones but " +
                                                       std::to_string(skeleton.names.size()) + " names");
  }
  if (skeleton.parents[0] != -1) {
    return make_error(ErrorCode::kInvalidArgument,
                      "bone 0 has parent " + std::to_string(skeleton.parents[0]) + ", expected -1 (the root)");
  }
  for (int j = 1; j < b; ++j) {
    const int parent = skeleton.parents[static_cast<size_t>(j)];
    if (parent < 0 || parent >= j) {
      return make_error(ErrorCode::kInvalidArgument, "bone " + std::to_string(j) + " has parent " +
                                                         std::to_string(parent) + ", expected 0 … " +
                                                         std::to_string(j - 1) + " (parents precede children)");
    }
  }
  for (int j = 0; j < b; ++j) {
    const Transform& rest = skeleton.rest[static_cast<size_t>(j)];
    if (!is_affine(rest)) {
      return make_error(ErrorCode::kInvalidArgument, "rest transform of bone " + std::to_string(j) +
                                                         " is not a finite affine matrix (last row 0 0 0 1)");
    }
    if (std::abs(rest.topLeftCorner<3, 3>().determinant()) < 1e-12) {
      return make_error(ErrorCode::kInvalidArgument, "rest transform of bone " + std::to_string(j) + " is singular");
    }
  }
  if (!skeleton.rest[0].isIdentity(1e-12)) {
    return make_error(ErrorCode::kInvalidArgument, "rest transform of the root (bone 0) must be the identity");
  }
  return Status::Ok();
}

Skeleton root_only_skeleton() {
  Skeleton skeleton;
  skeleton.parents = {-1};
  skeleton.rest = {Transform::Identity()};
  return skeleton;
}

Transform affine_inverse(const Transform& transform) {
  Transform inverse = Transform::Identity();
  const Eigen::Matrix3d linear_inverse = transform.topLeftCorner<3, 3>().inverse();
  inverse.topLeftCorner<3, 3>() = linear_inverse;
  inverse.topRightCorner<3, 1>() = -linear_inverse * transform.topRightCorner<3, 1>();
  return inverse;
}

Transform make_transform(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation) {
  Transform transform = Transform::Identity();
  transform.topLeftCorner<3, 3>() = rotation;
  transform.topRightCorner<3, 1>() = translation;
  return transform;
}

TransformList rest_joint_transforms(const Skeleton& skeleton) {
  return joint_transforms(skeleton, skeleton.rest);
}

TransformList global_transforms(const Skeleton& skeleton, const TransformList& joints) {
  assert(joints.size() == skeleton.parents.size());
  TransformList globals(joints.size());
  for (size_t j = 0; j < joints.size(); ++j) {
    const int parent = skeleton.parents[j];
    globals[j] = parent < 0 ? joints[j] : Transform(globals[static_cast<size_t>(parent)] * joints[j]);
  }
  return globals;
}

TransformList joint_transforms(const Skeleton& skeleton, const TransformList& globals) {
  assert(globals.size() == skeleton.parents.size());
  TransformList joints(globals.size());
  for (size_t j = 0; j < globals.size(); ++j) {
    const int parent = skeleton.parents[j];
    joints[j] = parent < 0 ? globals[j] : Transform(affine_inverse(globals[static_cast<size_t>(parent)]) * globals[j]);
  }
  return joints;
}

Status validate_pose(const Skeleton& skeleton, const TransformList& globals, const std::string& what) {
  if (globals.size() != skeleton.parents.size()) {
    return make_error(ErrorCode::kInvalidArgument, what + ": expected " + std::to_string(skeleton.parents.size()) +
                                                       " bone transforms, got " + std::to_string(globals.size()));
  }
  for (size_t j = 0; j < globals.size(); ++j) {
    if (!globals[j].allFinite()) {
      return make_error(ErrorCode::kInvalidArgument,
                        what + ": transform of bone " + std::to_string(j) + " has a NaN or infinite entry");
    }
    if (!is_affine(globals[j])) {
      return make_error(ErrorCode::kInvalidArgument,
                        what + ": transform of bone " + std::to_string(j) + " is not affine (last row must be 0 0 0 1)");
    }
  }
  return Status::Ok();
}

std::vector<TransformList> random_joint_rotation_poses(const Skeleton& skeleton, int count, double max_angle,
                                                       uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> angle(-max_angle, max_angle);
  const TransformList rest_joints = rest_joint_transforms(skeleton);
  std::vector<TransformList> poses;
  poses.reserve(static_cast<size_t>(std::max(count, 0)));
  for (int p = 0; p < count; ++p) {
    TransformList joints = rest_joints;
    for (size_t j = 1; j < joints.size(); ++j) {
      const double x = normal(engine), y = normal(engine), z = normal(engine);
      const Eigen::Vector3d axis = Eigen::Vector3d(x, y, z).normalized();
      joints[j].topLeftCorner<3, 3>() =
          joints[j].topLeftCorner<3, 3>() * Eigen::AngleAxisd(angle(engine), axis).toRotationMatrix();
    }
    poses.push_back(global_transforms(skeleton, joints));
  }
  return poses;
}

}  // namespace animspace::animation_space
