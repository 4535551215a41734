#include "core/animspace/bone_motions.h"

#include <algorithm>
#include <cassert>

#include <Eigen/LU>
#include <Eigen/SVD>

namespace animspace::animation_space {
namespace {

// The proper rotation nearest to the correlation H = Σ q xᵀ (Umeyama 1991): U diag(1, 1, ±1) Vᵀ.
Eigen::Matrix3d procrustes_rotation(const Eigen::Matrix3d& H) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * svd.matrixV().transpose();
}

// The sums one bone's best motion needs, accumulated over its influences (see the file comment of
// the header): S_ww = Σ w², S_wx = Σ w x, S_wq = Σ w q, S_qx = Σ q xᵀ.
struct MotionSums {
  double ww = 0;
  Eigen::Vector3d wx = Eigen::Vector3d::Zero();
  Eigen::Vector3d wq = Eigen::Vector3d::Zero();
  Eigen::Matrix3d qx = Eigen::Matrix3d::Zero();

  void add(const Eigen::Vector3d& x, double w, const Eigen::Vector3d& q) {
    ww += w * w;
    wx += w * x;
    wq += w * q;
    qx.noalias() += q * x.transpose();
  }

  Transform solve(const Transform& fallback) const {
    // Scale-aware "zero": the translation is undetermined when the weights all but vanish.
    if (!(ww > 0)) {
      const Eigen::Matrix3d H = qx;
      if (H.squaredNorm() == 0) return fallback;
      return make_transform(procrustes_rotation(H), fallback.topRightCorner<3, 1>());
    }
    // H = Σ (q − w q̄)(x − w x̄)ᵀ = S_qx − S_wq S_wxᵀ / S_ww.
    const Eigen::Matrix3d H = qx - wq * wx.transpose() / ww;
    const Eigen::Matrix3d R = H.squaredNorm() > 0 ? procrustes_rotation(H) : Eigen::Matrix3d(fallback.topLeftCorner<3, 3>());
    return make_transform(R, (wq - R * wx) / ww);
  }
};

template <typename Model>
TransformList solve_pose_of(const Model& model, const Eigen::Ref<const Eigen::RowVectorXf>& frame,
                            const MotionSolveOptions& options) {
  const MotionSkinning skinning = motion_skinning(model);
  const BoneInfluences by_bone = bone_influences(skinning.influences, model.skeleton.bone_count());
  TransformList globals = solve_motions(skinning, by_bone, frame_points(frame), options);
  for (size_t j = 0; j < globals.size(); ++j) globals[j] = globals[j] * model.skeleton.rest[j];
  return globals;
}

}  // namespace

MotionSkinning motion_skinning(const AnimationSpaceModel& model) {
  MotionSkinning out;
  out.influences = model.influences;
  out.y.resize(4, model.positions.cols());
  for (int k = 0; k < model.influences.influence_count(); ++k) {
    out.y.col(k) = model.skeleton.rest[static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)])] *
                   model.positions.col(k);
  }
  return out;
}

MotionSkinning motion_skinning(const LinearBlendModel& model) {
  MotionSkinning out;
  out.influences = model.influences;
  out.y.resize(4, model.influences.influence_count());
  for (int i = 0; i < model.vertex_count(); ++i) {
    for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
      out.y.col(k) << model.weights(k) * model.rest_points.col(i), model.weights(k);
    }
  }
  return out;
}

Transform fit_bone_motion(const Eigen::Matrix3Xd& x, const Eigen::VectorXd& w, const Eigen::Matrix3Xd& q,
                          const Transform& fallback) {
  assert(x.cols() == q.cols() && x.cols() == w.size());
  MotionSums sums;
  for (Eigen::Index i = 0; i < x.cols(); ++i) sums.add(x.col(i), w(i), q.col(i));
  return sums.solve(fallback);
}

BoneInfluences bone_influences(const InfluenceSets& influences, int bone_count) {
  BoneInfluences out;
  out.offsets.assign(static_cast<size_t>(bone_count) + 1, 0);
  for (int32_t bone : influences.bones) ++out.offsets[static_cast<size_t>(bone) + 1];
  for (int j = 0; j < bone_count; ++j) out.offsets[static_cast<size_t>(j) + 1] += out.offsets[static_cast<size_t>(j)];
  out.influence.resize(influences.bones.size());
  out.vertex.resize(influences.bones.size());
  std::vector<int32_t> next(out.offsets.begin(), out.offsets.end() - 1);
  for (int i = 0; i < influences.vertex_count(); ++i) {
    for (int k = influences.begin(i); k < influences.end(i); ++k) {
      const size_t slot = static_cast<size_t>(next[static_cast<size_t>(influences.bones[static_cast<size_t>(k)])]++);
      out.influence[slot] = k;
      out.vertex[slot] = i;
    }
  }
  return out;
}

void pose_with_motions(const MotionSkinning& skinning, const TransformList& motions, Eigen::Matrix3Xd& out) {
  out.setZero(3, skinning.vertex_count());
  for (int i = 0; i < skinning.vertex_count(); ++i) {
    for (int k = skinning.influences.begin(i); k < skinning.influences.end(i); ++k) {
      const Transform& M = motions[static_cast<size_t>(skinning.influences.bones[static_cast<size_t>(k)])];
      out.col(i).noalias() += M.topRows<3>() * skinning.y.col(k);
    }
  }
}

double refine_motions(const MotionSkinning& skinning, const BoneInfluences& by_bone, const Eigen::Matrix3Xd& frame,
                      TransformList& motions, int sweeps, const std::vector<int32_t>& fixed) {
  // The residual r_i = v_i − Σ_j M_j y_ij is kept up to date as bones change, so each bone costs
  // two passes over its own influences: q_i = r_i + M_j y_ij for the sums, then the update.
  Eigen::Matrix3Xd residual;
  pose_with_motions(skinning, motions, residual);
  residual = frame - residual;
  const int bones = static_cast<int>(motions.size());
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (int j = 0; j < bones; ++j) {
      if (std::find(fixed.begin(), fixed.end(), j) != fixed.end()) continue;
      const int begin = by_bone.offsets[static_cast<size_t>(j)], end = by_bone.offsets[static_cast<size_t>(j) + 1];
      if (begin == end) continue;
      Transform& M = motions[static_cast<size_t>(j)];
      MotionSums sums;
      for (int s = begin; s < end; ++s) {
        const auto y = skinning.y.col(by_bone.influence[static_cast<size_t>(s)]);
        const int i = by_bone.vertex[static_cast<size_t>(s)];
        sums.add(y.head<3>(), y(3), residual.col(i) + M.topRows<3>() * y);
      }
      const Transform updated = sums.solve(M);
      const Eigen::Matrix<double, 3, 4> change = updated.topRows<3>() - M.topRows<3>();
      for (int s = begin; s < end; ++s) {
        residual.col(by_bone.vertex[static_cast<size_t>(s)]).noalias() -=
            change * skinning.y.col(by_bone.influence[static_cast<size_t>(s)]);
      }
      M = updated;
    }
  }
  return residual.squaredNorm();
}

TransformList solve_motions(const MotionSkinning& skinning, const BoneInfluences& by_bone,
                            const Eigen::Matrix3Xd& frame, const MotionSolveOptions& options) {
  const int bones = static_cast<int>(by_bone.offsets.size()) - 1;
  TransformList motions(static_cast<size_t>(bones), Transform::Identity());
  // Start: each bone alone, as if it carried its vertices' whole weight — the rigid fit of the
  // rest positions to the frame, weighted by w² (x_i = w_i v̂_i, target w_i v_i).
  Eigen::Matrix3Xd rest = Eigen::Matrix3Xd::Zero(3, skinning.vertex_count());
  for (int i = 0; i < skinning.vertex_count(); ++i) {
    for (int k = skinning.influences.begin(i); k < skinning.influences.end(i); ++k) rest.col(i) += skinning.y.col(k).head<3>();
  }
  for (int j = 1; j < bones; ++j) {
    MotionSums sums;
    for (int s = by_bone.offsets[static_cast<size_t>(j)]; s < by_bone.offsets[static_cast<size_t>(j) + 1]; ++s) {
      const double w = skinning.y(3, by_bone.influence[static_cast<size_t>(s)]);
      const int i = by_bone.vertex[static_cast<size_t>(s)];
      sums.add(w * rest.col(i), w, w * frame.col(i));
    }
    motions[static_cast<size_t>(j)] = sums.solve(Transform::Identity());
  }
  double error = refine_motions(skinning, by_bone, frame, motions, 1);
  for (int sweep = 1; sweep < options.max_sweeps; ++sweep) {
    const double next = refine_motions(skinning, by_bone, frame, motions, 1);
    const bool settled = error - next <= options.tolerance * error;
    error = next;
    if (settled) break;
  }
  return motions;
}

TransformList solve_pose(const AnimationSpaceModel& model, const Eigen::Ref<const Eigen::RowVectorXf>& frame,
                         const MotionSolveOptions& options) {
  return solve_pose_of(model, frame, options);
}

TransformList solve_pose(const LinearBlendModel& model, const Eigen::Ref<const Eigen::RowVectorXf>& frame,
                         const MotionSolveOptions& options) {
  return solve_pose_of(model, frame, options);
}

Eigen::Matrix3Xd frame_points(const Eigen::Ref<const Eigen::RowVectorXf>& frame) {
  assert(frame.size() % 3 == 0);
  Eigen::Matrix3Xd out(3, frame.size() / 3);
  for (Eigen::Index i = 0; i < out.cols(); ++i) out.col(i) = frame.segment<3>(3 * i).transpose().cast<double>();
  return out;
}

}  // namespace animspace::animation_space
