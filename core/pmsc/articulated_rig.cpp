#include "core/pmsc/articulated_rig.h"

#include <cmath>
#include <deque>
#include <limits>
#include <string>

#include <Eigen/Cholesky>

#include "core/common/parallel.h"
#include "core/pmsc/articulated.h"

namespace animspace::pmsc {
namespace {

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

// h_ij of point i and bone j: the first row of the basis's 3 × 12 block (articulated.h), whose
// other rows repeat it in their own four columns (make_subspace refuses a basis where they do not).
Eigen::Vector4d skinning_term(const PmscModel& m, long i, int j) {
  return m.basis.block<1, 4>(3 * i, static_cast<long>(kBoneCoordinates) * j).transpose().cast<double>();
}

// B_i = Σ_j w_ij A_j of point i at one answer.
Eigen::Matrix3d blended_linear_map(const ArticulatedRig& rig, const Eigen::VectorXd& p, long i) {
  Eigen::Matrix3d blended = Eigen::Matrix3d::Zero();
  for (int32_t e = rig.offsets[static_cast<size_t>(i)]; e < rig.offsets[static_cast<size_t>(i) + 1]; ++e) {
    const long column = static_cast<long>(kBoneCoordinates) * rig.bones[static_cast<size_t>(e)];
    for (int r = 0; r < 3; ++r) blended.row(r) += rig.weights[static_cast<size_t>(e)] * p.segment<3>(column + 4 * r).transpose();
  }
  return blended;
}

// The least-squares morphs of articulated_rig.h for point i: unknowns x = (μ'_i, d_i1 … d_ir),
// each answer's rows B (μ' + Σ p_k d_k) against μ_i + Σ p_k R_ik, normal equations assembled as
// Σ (κ κᵀ) ⊗ (BᵀB) with κ = (1, p_1 … p_r), ridge toward (μ_i, R_i·).
void fit_point_targets(const PmscModel& m, const ArticulatedRig& rig, const std::vector<Eigen::VectorXd>& poses,
                       double relative_ridge, long i, Eigen::VectorXd& x) {
  const int r = m.residual_components;
  const long skinning = static_cast<long>(kBoneCoordinates) * m.bone_count;
  const int n = 3 * (r + 1);
  Eigen::VectorXd plain(n);
  plain.head<3>() = m.mean.segment<3>(3 * i).cast<double>();
  for (int k = 0; k < r; ++k) plain.segment<3>(3 * (k + 1)) = m.basis.block<3, 1>(3 * i, skinning + k).cast<double>();
  Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd kappa(r + 1);
  for (const Eigen::VectorXd& p : poses) {
    const Eigen::Matrix3d B = blended_linear_map(rig, p, i);
    const Eigen::Matrix3d BtB = B.transpose() * B;
    kappa(0) = 1;
    kappa.tail(r) = p.tail(r);
    Eigen::Vector3d target = plain.head<3>();
    for (int k = 0; k < r; ++k) target += kappa(k + 1) * plain.segment<3>(3 * (k + 1));
    const Eigen::Vector3d Bt_target = B.transpose() * target;
    for (int a = 0; a <= r; ++a) {
      rhs.segment<3>(3 * a) += kappa(a) * Bt_target;
      for (int b = 0; b <= a; ++b) normal.block<3, 3>(3 * a, 3 * b) += (kappa(a) * kappa(b)) * BtB;
    }
  }
  const double ridge = relative_ridge * normal.diagonal().mean() + std::numeric_limits<double>::min();
  normal.diagonal().array() += ridge;
  rhs += ridge * plain;
  x = normal.selfadjointView<Eigen::Lower>().ldlt().solve(rhs);
}

}  // namespace

Result<ArticulatedRig> articulated_rig(const PmscModel& m, const Eigen::MatrixX3d* placement,
                                       const std::vector<Eigen::VectorXd>* fit_to, double ridge) {
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
  if (fit_to == nullptr || fit_to->empty()) return rig;
  for (size_t f = 0; f < fit_to->size(); ++f) {
    if ((*fit_to)[f].size() != m.basis_size()) {
      return invalid("fit_to[" + std::to_string(f) + "] has " + std::to_string((*fit_to)[f].size()) +
                     " coordinates, expected M = " + std::to_string(m.basis_size()));
    }
  }
  parallel_for_chunks(N, 64, [&](int64_t begin, int64_t end) {
    Eigen::VectorXd x;
    for (long i = begin; i < end; ++i) {
      fit_point_targets(m, rig, *fit_to, ridge, i, x);
      rig.bind_points.row(i) = rest.row(i) + x.head<3>().transpose();
      for (int k = 0; k < m.residual_components; ++k) rig.residual_targets[static_cast<size_t>(k)].row(i) = x.segment<3>(3 * (k + 1)).transpose();
    }
  });
  return rig;
}

namespace {

// The model's f̂ of each answer (mean + A p in double, moved to the world), N × 3 each: what
// every candidate rig is measured against, made once.
std::vector<Eigen::MatrixX3d> model_points(const PmscModel& m, const std::vector<PoseEstimate>& answers) {
  const Eigen::MatrixXd A = m.basis.cast<double>();
  std::vector<Eigen::MatrixX3d> out;
  out.reserve(answers.size());
  for (const PoseEstimate& answer : answers) {
    const Eigen::VectorXd f = m.mean.cast<double>() + A * answer.coordinates;
    Eigen::MatrixX3d points(m.point_count, 3);
    for (long i = 0; i < m.point_count; ++i) {
      const Eigen::Vector3d x = f.segment<3>(3 * i);
      points.row(i) = (m.aligned ? answer.alignment.apply(x) : x).transpose();
    }
    out.push_back(std::move(points));
  }
  return out;
}

// The worst point distance between the rig posed at each answer and `expected` (model_points),
// over answers [begin, end).
double worst_deviation(const PmscModel& m, const ArticulatedRig& rig, const std::vector<PoseEstimate>& answers,
                       const std::vector<Eigen::MatrixX3d>& expected, size_t begin, size_t end) {
  double worst = 0;
  for (size_t f = begin; f < end; ++f) {
    const Eigen::MatrixX3d posed = pose_rig(m, rig, answers[f].coordinates, answers[f].alignment);
    worst = std::max(worst, (posed - expected[f]).rowwise().norm().maxCoeff());
  }
  return worst;
}

}  // namespace

Result<ArticulatedRig> fit_articulated_rig(const PmscModel& m, const Eigen::MatrixX3d* placement,
                                           const std::vector<PoseEstimate>& answers, RigFit& report) {
  report = RigFit{};
  auto plain = articulated_rig(m, placement);
  if (!plain) return plain;
  report.ridge = std::numeric_limits<double>::infinity();
  const std::vector<Eigen::MatrixX3d> expected = model_points(m, answers);
  report.plain_max_deviation = report.max_deviation = worst_deviation(m, *plain, answers, expected, 0, answers.size());
  const size_t seen = static_cast<size_t>(static_cast<double>(answers.size()) * kTargetFitShare);
  if (answers.size() < 5 || seen == 0 || seen == answers.size()) return plain;
  std::vector<Eigen::VectorXd> first, all;
  for (size_t f = 0; f < answers.size(); ++f) {
    all.push_back(answers[f].coordinates);
    if (f < seen) first.push_back(answers[f].coordinates);
  }
  report.held_out = static_cast<long>(answers.size() - seen);
  report.held_out_plain_max_deviation = report.held_out_max_deviation =
      worst_deviation(m, *plain, answers, expected, seen, answers.size());
  for (const double ridge : kTargetRidges) {
    auto candidate = articulated_rig(m, placement, &first, ridge);
    if (!candidate) return candidate;
    const double held_out = worst_deviation(m, *candidate, answers, expected, seen, answers.size());
    if (held_out < report.held_out_max_deviation) {
      report.held_out_max_deviation = held_out;
      report.ridge = ridge;
    }
  }
  if (!std::isfinite(report.ridge)) return plain;
  auto fitted = articulated_rig(m, placement, &all, report.ridge);
  if (!fitted) return fitted;
  report.max_deviation = worst_deviation(m, *fitted, answers, expected, 0, answers.size());
  return fitted;
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
