#include "core/pmsc/articulated_rig.h"

#include <cmath>
#include <deque>
#include <string>

#include "core/pmsc/articulated.h"

namespace animspace::pmsc {
namespace {

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

// h_ij of point i and bone j: the first row of the basis's 3 × 12 block (articulated.h), whose
// other rows repeat it in their own four columns (make_subspace refuses a basis where they do not).
Eigen::Vector4d skinning_term(const PmscModel& m, long i, int j) {
  return m.basis.block<1, 4>(3 * i, static_cast<long>(kBoneCoordinates) * j).transpose().cast<double>();
}

}  // namespace

Result<ArticulatedRig> articulated_rig(const PmscModel& m, const Eigen::MatrixX3d* placement) {
  if (m.subspace_kind != SubspaceKind::kArticulated) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "a skinned rig is held only by an articulated model (subspace_kind articulated); this one is "
                      "linear");
  }
  if (m.channel_count != 3 || m.cross) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "a skinned rig needs an articulated model of 3-D points that are its own control points");
  }
  const long N = m.point_count;
  const int B = m.bone_count;
  if (placement != nullptr && placement->rows() != N) {
    return invalid("placement has " + std::to_string(placement->rows()) + " rows, expected N = " + std::to_string(N));
  }
  ArticulatedRig rig;
  rig.offsets.reserve(static_cast<size_t>(N) + 1);
  rig.offsets.push_back(0);
  std::vector<Eigen::Vector3d> offsets_of;  // d_ij, alongside bones
  std::vector<std::vector<long>> points_of(static_cast<size_t>(B));
  for (long i = 0; i < N; ++i) {
    double sum = 0;
    const size_t first = rig.bones.size();
    for (int j = 0; j < B; ++j) {
      const Eigen::Vector4d h = skinning_term(m, i, j);
      if (h(3) == 0 && h.head<3>().isZero()) continue;
      if (!(h(3) > 0)) {
        return invalid("pmsc model: point " + std::to_string(i) + " has weight " + std::to_string(h(3)) +
                       " on bone " + std::to_string(j) + ", expected > 0 where its skinning term is not zero");
      }
      rig.bones.push_back(j);
      rig.weights.push_back(h(3));
      offsets_of.push_back(h.head<3>() / h(3));
      points_of[static_cast<size_t>(j)].push_back(i);
      sum += h(3);
    }
    if (rig.bones.size() == first) {
      return invalid("pmsc model: point " + std::to_string(i) + " depends on no bone");
    }
    for (size_t e = first; e < rig.bones.size(); ++e) rig.weights[e] /= sum;
    rig.offsets.push_back(static_cast<int32_t>(rig.bones.size()));
  }

  // c and p̂ from the offsets, one set of connected bones at a time: its first bone at the
  // origin, then breadth first, each point placed from a placed bone (p̂_i = c_j + d_ij) and each
  // of its bones from it (c_k = p̂_i − d_ik).
  rig.centres = Eigen::MatrixX3d::Zero(B, 3);
  rig.bone_used.assign(static_cast<size_t>(B), false);
  Eigen::MatrixX3d rest(N, 3);
  std::vector<bool> placed(static_cast<size_t>(N), false);
  for (int root = 0; root < B; ++root) {
    if (rig.bone_used[static_cast<size_t>(root)] || points_of[static_cast<size_t>(root)].empty()) continue;
    std::vector<long> members;
    std::vector<int> set_bones{root};
    std::deque<int> queue{root};
    rig.bone_used[static_cast<size_t>(root)] = true;
    while (!queue.empty()) {
      const int j = queue.front();
      queue.pop_front();
      for (const long i : points_of[static_cast<size_t>(j)]) {
        if (placed[static_cast<size_t>(i)]) continue;
        const int32_t begin = rig.offsets[static_cast<size_t>(i)], end = rig.offsets[static_cast<size_t>(i) + 1];
        for (int32_t e = begin; e < end; ++e) {
          if (rig.bones[static_cast<size_t>(e)] == j) rest.row(i) = rig.centres.row(j) + offsets_of[static_cast<size_t>(e)].transpose();
        }
        placed[static_cast<size_t>(i)] = true;
        members.push_back(i);
        for (int32_t e = begin; e < end; ++e) {
          const int k = rig.bones[static_cast<size_t>(e)];
          if (rig.bone_used[static_cast<size_t>(k)]) continue;
          rig.bone_used[static_cast<size_t>(k)] = true;
          rig.centres.row(k) = rest.row(i) - offsets_of[static_cast<size_t>(e)].transpose();
          set_bones.push_back(k);
          queue.push_back(k);
        }
      }
    }
    // The set's translation: its points' centroid at the placement's, or at the origin.
    Eigen::RowVector3d shift = Eigen::RowVector3d::Zero();
    for (const long i : members) {
      shift += (placement != nullptr ? Eigen::RowVector3d(placement->row(i)) : Eigen::RowVector3d::Zero()) - rest.row(i);
    }
    shift /= static_cast<double>(members.size());
    for (const long i : members) rest.row(i) += shift;
    for (const int k : set_bones) rig.centres.row(k) += shift;
  }

  rig.bind_points = rest;
  for (long i = 0; i < N; ++i) rig.bind_points.row(i) += m.mean.segment<3>(3 * i).cast<double>().transpose();
  const long skinning = static_cast<long>(kBoneCoordinates) * B;
  for (int k = 0; k < m.residual_components; ++k) {
    Eigen::MatrixX3d target(N, 3);
    for (long i = 0; i < N; ++i) target.row(i) = m.basis.block<3, 1>(3 * i, skinning + k).cast<double>().transpose();
    rig.residual_targets.push_back(std::move(target));
  }
  return rig;
}

Eigen::Matrix4d bone_world_transform(const PmscModel& m, const Eigen::VectorXd& coordinates,
                                     const geometry::RigidTransform& alignment, int bone) {
  Eigen::Matrix4d bone_map = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) bone_map(r, c) = coordinates(kBoneCoordinates * bone + 4 * r + c);
  }
  Eigen::Matrix4d world = Eigen::Matrix4d::Identity();
  if (m.aligned) {
    world.topLeftCorner<3, 3>() = alignment.rotation;
    world.topRightCorner<3, 1>() = alignment.translation;
  }
  return world * bone_map;
}

Eigen::MatrixX3d pose_rig(const PmscModel& m, const ArticulatedRig& rig, const Eigen::VectorXd& coordinates,
                          const geometry::RigidTransform& alignment) {
  const long N = m.point_count;
  const long skinning = static_cast<long>(kBoneCoordinates) * m.bone_count;
  std::vector<Eigen::Matrix4d> joint_matrices(static_cast<size_t>(m.bone_count));
  for (int j = 0; j < m.bone_count; ++j) {
    Eigen::Matrix4d unbind = Eigen::Matrix4d::Identity();
    unbind.topRightCorner<3, 1>() = -rig.centres.row(j).transpose();
    joint_matrices[static_cast<size_t>(j)] = bone_world_transform(m, coordinates, alignment, j) * unbind;
  }
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(N, 3);
  for (long i = 0; i < N; ++i) {
    Eigen::Vector4d morphed(rig.bind_points(i, 0), rig.bind_points(i, 1), rig.bind_points(i, 2), 1);
    for (size_t k = 0; k < rig.residual_targets.size(); ++k) {
      morphed.head<3>() += coordinates(skinning + static_cast<long>(k)) * rig.residual_targets[k].row(i).transpose();
    }
    Eigen::Vector4d posed = Eigen::Vector4d::Zero();
    for (int32_t e = rig.offsets[static_cast<size_t>(i)]; e < rig.offsets[static_cast<size_t>(i) + 1]; ++e) {
      posed += rig.weights[static_cast<size_t>(e)] *
               (joint_matrices[static_cast<size_t>(rig.bones[static_cast<size_t>(e)])] * morphed);
    }
    out.row(i) = posed.head<3>().transpose();
  }
  return out;
}

}  // namespace animspace::pmsc
