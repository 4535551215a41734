#include "core/animspace/fit_sequence.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/common/timing.h"

namespace animspace::animation_space {
namespace {

FitExamples make_examples(const FrameMatrix& frames, const std::vector<TransformList>& poses) {
  FitExamples examples;
  examples.poses = poses;
  examples.meshes = frames;
  return examples;
}

template <typename Model>
ReconstructionError reconstruction_error_of(const Model& model, const std::vector<TransformList>& poses,
                                            const FrameMatrix& frames) {
  assert(static_cast<Eigen::Index>(poses.size()) == frames.rows());
  ReconstructionError error;
  double sum = 0;
  PointMatrix posed;
  for (size_t f = 0; f < poses.size(); ++f) {
    evaluate(model, poses[f], posed);
    const Eigen::Map<const PointMatrix> captured(frames.row(static_cast<Eigen::Index>(f)).data(), posed.rows(), 3);
    const Eigen::VectorXd distances = (posed - captured).cast<double>().rowwise().norm();
    sum += distances.squaredNorm();
    error.max = std::max(error.max, distances.maxCoeff());
  }
  error.rms = std::sqrt(sum / (static_cast<double>(poses.size()) * static_cast<double>(model.vertex_count())));
  return error;
}

}  // namespace

ReconstructionError reconstruction_error(const AnimationSpaceModel& model, const std::vector<TransformList>& poses,
                                         const FrameMatrix& frames) {
  return reconstruction_error_of(model, poses, frames);
}

ReconstructionError reconstruction_error(const LinearBlendModel& model, const std::vector<TransformList>& poses,
                                         const FrameMatrix& frames) {
  return reconstruction_error_of(model, poses, frames);
}

Result<SequenceSkeleton> fit_sequence_skeleton(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceFitOptions& options, SequenceFitReport* report) {
  SequenceFitReport local;
  SequenceFitReport& out = report ? *report : local;

  // 1. Rigid parts and their hierarchy stand in for the user-drawn skeleton of §4.1.4.
  auto start = std::chrono::steady_clock::now();
  auto segmentation = segment_rigid_parts(reference.V, reference.F, frames, options.segmentation);
  if (!segmentation) return segmentation.error();
  out.segmentation_seconds = seconds_since(start);
  out.segmentation_rms = segmentation->rms_error;

  // 2. Skeleton fitting from the core vertices, joints started at the part boundaries (u_j).
  start = std::chrono::steady_clock::now();
  Skeleton user;
  user.parents = segmentation->parents;
  for (int j = 0; j < segmentation->bone_count(); ++j) {
    user.rest.push_back(make_transform(Eigen::Matrix3d::Identity(), segmentation->joint_positions.row(j).transpose()));
  }
  auto fitted = fit_skeleton(reference.V, frames, user, segmentation->core_vertices, options.skeleton, &out.skeleton);
  if (!fitted) return fitted.error();
  out.skeleton_seconds = seconds_since(start);

  // 3. Influence sets grown from the parts (§4.1.1).
  auto influences = grow_influence_sets(fitted->skeleton, segmentation->labels, reference.F, options.influences);
  if (!influences) return influences.error();

  SequenceSkeleton result;
  result.skeleton = std::move(fitted->skeleton);
  result.core_vertices = std::move(segmentation->core_vertices);
  for (int32_t bone : out.skeleton.inherited_bones) result.core_vertices[static_cast<size_t>(bone)].clear();
  result.labels = std::move(segmentation->labels);
  result.influences = std::move(*influences);
  result.training_poses = std::move(fitted->poses);
  return result;
}

Result<AnimationSpaceModel> fit_sequence_model(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceSkeleton& skeleton, const FitOptions& options,
                                               FitReport* report) {
  auto model = fit_animation_space(skeleton.skeleton, make_examples(frames, skeleton.training_poses), reference.F,
                                   skeleton.influences, options, report);
  if (!model) return model.error();
  model->faces = reference.F;
  return model;
}

Result<LinearBlendModel> fit_sequence_linear_blend(const TriangleMesh& reference, const FrameMatrix& frames,
                                                   const SequenceSkeleton& skeleton, const FitOptions& options,
                                                   FitReport* report) {
  auto model = fit_linear_blend(skeleton.skeleton, reference.V, make_examples(frames, skeleton.training_poses),
                                reference.F, skeleton.influences, options, report);
  if (!model) return model.error();
  model->faces = reference.F;
  return model;
}

Result<AnimationSpaceModel> fit_sequence(const TriangleMesh& reference, const FrameMatrix& frames,
                                         const SequenceFitOptions& options, SequenceFitReport* report) {
  SequenceFitReport local;
  SequenceFitReport& out = report ? *report : local;
  auto skeleton = fit_sequence_skeleton(reference, frames, options, &out);
  if (!skeleton) return skeleton.error();
  const auto start = std::chrono::steady_clock::now();
  auto model = fit_sequence_model(reference, frames, *skeleton, options.fit, &out.fit);
  out.fit_seconds = seconds_since(start);
  return model;
}

TransformList estimate_pose(const SequenceSkeleton& skeleton, const PointMatrix& reference,
                            const Eigen::Ref<const Eigen::RowVectorXf>& frame) {
  assert(frame.size() == 3 * reference.rows());
  const int b = skeleton.skeleton.bone_count();
  TransformList motions(static_cast<size_t>(b), Transform::Identity());
  TransformList globals(static_cast<size_t>(b), Transform::Identity());
  for (int j = 1; j < b; ++j) {
    const auto& core = skeleton.core_vertices[static_cast<size_t>(j)];
    Eigen::Matrix3Xd rest(3, static_cast<Eigen::Index>(core.size())), posed(3, static_cast<Eigen::Index>(core.size()));
    for (size_t c = 0; c < core.size(); ++c) {
      rest.col(static_cast<Eigen::Index>(c)) = reference.row(core[c]).transpose().cast<double>();
      posed.col(static_cast<Eigen::Index>(c)) = frame.segment<3>(3L * core[c]).transpose().cast<double>();
    }
    // A bone whose core vertices cannot fix a rotation moves with its parent, as in fitting.
    motions[static_cast<size_t>(j)] = determines_rigid_motion(rest)
                                          ? fit_rigid_motion(rest, posed)
                                          : motions[static_cast<size_t>(skeleton.skeleton.parents[static_cast<size_t>(j)])];
    globals[static_cast<size_t>(j)] = motions[static_cast<size_t>(j)] * skeleton.skeleton.rest[static_cast<size_t>(j)];
  }
  return globals;
}

}  // namespace animspace::animation_space
