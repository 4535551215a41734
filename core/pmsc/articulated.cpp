#include "core/pmsc/articulated.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Cholesky>

#include "core/animspace/segmentation.h"
#include "core/animspace/skinning_decomposition.h"
#include "core/common/kernels.h"
#include "core/pmsc/training_matrix.h"

namespace animspace::pmsc {
namespace {

Error invalid(const std::string& message) { return make_error(ErrorCode::kInvalidArgument, message); }

// Up to four points among `candidates` that fix an affine map: the heaviest, then each next the
// farthest from the affine hull of those before (a point, a line, a plane).
std::vector<int> spanning_points(const Eigen::MatrixX3d& rest, const std::vector<int>& candidates,
                                 const std::vector<double>& weights) {
  std::vector<int> chosen;
  if (candidates.empty()) return chosen;
  const size_t heaviest = static_cast<size_t>(std::max_element(weights.begin(), weights.end()) - weights.begin());
  chosen.push_back(candidates[heaviest]);
  // Orthonormal directions of the hull so far; a candidate's distance is what they leave of it.
  std::vector<Eigen::Vector3d> directions;
  const Eigen::Vector3d origin = rest.row(chosen[0]).transpose();
  while (chosen.size() < 4) {
    double farthest = 0;
    int best = -1;
    Eigen::Vector3d best_offset = Eigen::Vector3d::Zero();
    for (int point : candidates) {
      Eigen::Vector3d offset = rest.row(point).transpose() - origin;
      for (const Eigen::Vector3d& d : directions) offset -= d.dot(offset) * d;
      const double distance = offset.squaredNorm();
      if (distance > farthest) {
        farthest = distance;
        best = point;
        best_offset = offset;
      }
    }
    // Nothing off the hull (a bone of collinear or coincident points): what there is fixes what
    // it can; the regularisation of the projection does the rest.
    if (best < 0 || !(farthest > 1e-24 * (1 + origin.squaredNorm()))) break;
    chosen.push_back(best);
    directions.push_back(best_offset.normalized());
  }
  return chosen;
}

}  // namespace

int default_bone_count(long point_count) {
  return static_cast<int>(std::max<long>(1, std::min<long>(kArticulatedDefaultBones, point_count / kPointsPerBone)));
}

Eigen::MatrixXd skinning_columns(const Eigen::MatrixX3d& rest, const animation_space::InfluenceSets& influences,
                                 const Eigen::VectorXd& weights, int bone_count, const Eigen::MatrixX3d& centres) {
  const long N = rest.rows();
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(3 * N, static_cast<long>(kBoneCoordinates) * bone_count);
  for (long i = 0; i < N; ++i) {
    for (int k = influences.begin(static_cast<int>(i)); k < influences.end(static_cast<int>(i)); ++k) {
      const int bone = influences.bones[static_cast<size_t>(k)];
      if (bone < 1) continue;  // the root carries no transform
      const double w = weights(k);
      const Eigen::RowVector3d local = rest.row(i) - centres.row(bone - 1);
      const long first = static_cast<long>(kBoneCoordinates) * (bone - 1);
      for (int r = 0; r < 3; ++r) {
        // Row r of M_j [p̂ − c_j; 1]: its four numbers a_r0 a_r1 a_r2 t_r.
        for (int c = 0; c < 3; ++c) L(3 * i + r, first + 4 * r + c) += w * local(c);
        L(3 * i + r, first + 4 * r + 3) += w;
      }
    }
  }
  return L;
}

Result<ArticulatedSkinning> fit_articulated_skinning(const FrameMatrix& frames, const FaceMatrix& faces,
                                                     int bone_count, const ProgressCallback& progress) {
  const long F = frames.rows();
  if (F < 2) return invalid("frames: the articulated subspace needs at least 2 training frames, got " + std::to_string(F));
  if (frames.cols() == 0 || frames.cols() % 3 != 0) {
    return invalid("frames: the articulated subspace needs positions (3 values per point), got " +
                   std::to_string(frames.cols()) + " values per frame");
  }
  const long N = frames.cols() / 3;
  if (bone_count < 1 || bone_count > N) {
    return invalid("bone_count: expected 1 … " + std::to_string(N) + " (the points), got " + std::to_string(bone_count));
  }

  // (1) Rigid parts, (2) the skinning decomposition, on the first frame as the rest pose.
  const PointMatrix rest_float = Eigen::Map<const PointMatrix>(frames.row(0).data(), N, 3);
  animation_space::SegmentationOptions segmentation_options;
  segmentation_options.bone_count = bone_count;
  auto segmentation = animation_space::segment_rigid_parts(rest_float, faces, frames, segmentation_options);
  if (!segmentation) return segmentation.error();
  animation_space::DecompositionOptions decomposition_options;
  decomposition_options.tolerance = kDecompositionTolerance;
  auto decomposition =
      animation_space::decompose_skinning(rest_float, faces, frames, segmentation->labels, segmentation->transforms,
                                          decomposition_options, nullptr, progress);
  if (!decomposition) return decomposition.error();
  const animation_space::InfluenceSets& influences = decomposition->weights.influences;
  const Eigen::VectorXd& weights = decomposition->weights.weights;
  const int B = segmentation->bone_count() - 1;

  // Bone centres: each bone's weighted centroid (a bone that lost every weight keeps the origin;
  // its columns are zero and the projection's regularisation leaves its numbers at 0).
  const Eigen::MatrixX3d rest = rest_float.cast<double>();
  Eigen::MatrixX3d centres = Eigen::MatrixX3d::Zero(B, 3);
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(B);
  std::vector<std::vector<int>> dominated(static_cast<size_t>(B));
  std::vector<std::vector<double>> dominated_weight(static_cast<size_t>(B));
  for (long i = 0; i < N; ++i) {
    int heaviest = -1;
    double heaviest_weight = 0;
    for (int k = influences.begin(static_cast<int>(i)); k < influences.end(static_cast<int>(i)); ++k) {
      const int bone = influences.bones[static_cast<size_t>(k)];
      if (bone < 1) continue;
      centres.row(bone - 1) += weights(k) * rest.row(i);
      mass(bone - 1) += weights(k);
      if (weights(k) > heaviest_weight) {
        heaviest_weight = weights(k);
        heaviest = bone;
      }
    }
    if (heaviest > 0) {
      dominated[static_cast<size_t>(heaviest - 1)].push_back(static_cast<int>(i));
      dominated_weight[static_cast<size_t>(heaviest - 1)].push_back(heaviest_weight);
    }
  }
  for (int j = 0; j < B; ++j) {
    if (mass(j) > 0) centres.row(j) /= mass(j);
  }

  ArticulatedSkinning out;
  out.bone_count = B;
  out.columns = skinning_columns(rest, influences, weights, B, centres);
  for (int j = 0; j < B; ++j) {
    for (int point : spanning_points(rest, dominated[static_cast<size_t>(j)], dominated_weight[static_cast<size_t>(j)])) {
      out.coverage_points.push_back(point);
    }
  }

  // (3) Every frame's transforms by least squares over all its points, Q = (LᵀL)⁻¹ LᵀT, and what
  // they leave. A ridge of 1e-12 of the Gram's trace keeps a bone without weights solvable.
  // T is read from the frames' own bytes (training_matrix.h), not copied to double: beside the
  // residuals it would be a second R × F double (issue #53 item 2).
  const long R = 3 * N, P = out.columns.cols();
  const TrainingMatrix T(frames.data(), R, F);
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(P, P);
  gram_lower_serial(R, P, out.columns.data(), R, gram.data(), P);
  gram = gram.selfadjointView<Eigen::Lower>();
  gram.diagonal().array() += 1e-12 * std::max(gram.trace(), 1e-300) / static_cast<double>(P);
  const Eigen::MatrixXd Q = gram.ldlt().solve(T.transposed_times(out.columns));
  out.residuals.resize(R, F);
  gemm_serial(R, P, F, out.columns.data(), R, Q.data(), P, 0.0, out.residuals.data(), R);
  out.residuals = frames.transpose().cast<double>() - out.residuals;  // coefficient-wise: no temporary
  out.rms = std::sqrt(out.residuals.squaredNorm() / static_cast<double>(N * F));
  return out;
}

}  // namespace animspace::pmsc
