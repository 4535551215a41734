#include "core/animspace/fit_sequence.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>

#include "core/animspace/bone_motions.h"
#include "core/common/parallel.h"
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
                                               const SequenceFitOptions& options, SequenceFitReport* report,
                                               const ProgressCallback& progress) {
  SequenceFitReport local;
  SequenceFitReport& out = report ? *report : local;

  // 1. Rigid parts and their hierarchy stand in for the user-drawn skeleton of §4.1.4.
  auto start = std::chrono::steady_clock::now();
  auto segmentation = segment_rigid_parts(reference.V, reference.F, frames, options.segmentation);
  if (!segmentation) return segmentation.error();
  out.segmentation_seconds = seconds_since(start);
  out.segmentation_rms = segmentation->rms_error;

  start = std::chrono::steady_clock::now();
  Skeleton user;
  user.parents = segmentation->parents;
  for (int j = 0; j < segmentation->bone_count(); ++j) {
    user.rest.push_back(make_transform(Eigen::Matrix3d::Identity(), segmentation->joint_positions.row(j).transpose()));
  }
  SequenceSkeleton result;
  if (options.decompose) {
    // 2–3. The alternating optimisation, then the joints of its motions (eq. 4.6), joints started
    //      at the part boundaries (u_j).
    auto decomposition = decompose_skinning(reference.V, reference.F, frames, segmentation->labels,
                                            segmentation->transforms, options.decomposition, &out.decomposition,
                                            progress);
    if (!decomposition) return decomposition.error();
    auto skeleton = skeleton_from_motions(user, decomposition->motions, options.skeleton.joint_regularisation);
    if (!skeleton) return skeleton.error();
    result.skeleton = std::move(*skeleton);
    result.influences = std::move(decomposition->weights.influences);
    result.weights = std::move(decomposition->weights.weights);
    for (TransformList& pose : decomposition->motions) {
      for (size_t j = 0; j < pose.size(); ++j) pose[j] = pose[j] * result.skeleton.rest[j];
    }
    result.training_poses = std::move(decomposition->motions);
  } else {
    // 2. Skeleton fitting from the core vertices, joints started at the part boundaries (u_j).
    auto fitted = fit_skeleton(reference.V, frames, user, segmentation->core_vertices, options.skeleton, &out.skeleton);
    if (!fitted) return fitted.error();
    // 3. Influence sets grown from the parts (§4.1.1).
    auto influences = grow_influence_sets(fitted->skeleton, segmentation->labels, reference.F, options.influences);
    if (!influences) return influences.error();
    result.skeleton = std::move(fitted->skeleton);
    result.influences = std::move(*influences);
    result.training_poses = std::move(fitted->poses);
  }
  out.skeleton_seconds = seconds_since(start);
  result.labels = std::move(segmentation->labels);
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
  if (skeleton.weights.size() > 0) {
    LinearBlendModel model;
    model.skeleton = skeleton.skeleton;
    model.faces = reference.F;
    model.rest_points = reference.V.transpose().cast<double>();
    model.influences = skeleton.influences;
    model.weights = skeleton.weights;
    if (report) {
      *report = FitReport{};
      report->vertices = model.vertex_count();
      report->examples = static_cast<int>(frames.rows());
      const ReconstructionError error = reconstruction_error(model, skeleton.training_poses, frames);
      report->residual_rms = error.rms;
      report->residual_max = error.max;
    }
    return model;
  }
  auto model = fit_linear_blend(skeleton.skeleton, reference.V, make_examples(frames, skeleton.training_poses),
                                reference.F, skeleton.influences, options, report);
  if (!model) return model.error();
  model->faces = reference.F;
  return model;
}

Result<AnimationSpaceModel> refine_animation_space(const FrameMatrix& frames, AnimationSpaceModel model,
                                                   std::vector<TransformList>& poses, const FitOptions& options,
                                                   int rounds, FitReport* report, const ProgressCallback& progress) {
  assert(static_cast<Eigen::Index>(poses.size()) == frames.rows());
  const FaceMatrix faces = model.faces;
  report_progress(progress, "animation-space refinement", 0, rounds);
  for (int round = 0; round < rounds; ++round) {
    // Motions M_j = G_j Ĝ_j⁻¹ with the model fixed, every frame on its own.
    const MotionSkinning skinning = motion_skinning(model);
    const BoneInfluences by_bone = bone_influences(skinning.influences, model.bone_count());
    const Skeleton& skeleton = model.skeleton;
    parallel_for_chunks(static_cast<int64_t>(poses.size()), 1, [&](int64_t begin, int64_t end) {
      for (int64_t f = begin; f < end; ++f) {
        TransformList& G = poses[static_cast<size_t>(f)];
        TransformList motions(G.size());
        for (size_t j = 0; j < G.size(); ++j) motions[j] = G[j] * affine_inverse(skeleton.rest[j]);
        refine_motions(skinning, by_bone, frame_points(frames.row(f)), motions, 2);
        for (size_t j = 0; j < G.size(); ++j) G[j] = motions[j] * skeleton.rest[j];
      }
    });
    // The model with the motions fixed.
    FitExamples examples;
    examples.poses = poses;
    examples.meshes = frames;
    auto refit = fit_animation_space(skeleton, examples, faces, model.influences, options, report);
    if (!refit) return refit.error();
    model = std::move(*refit);
    model.faces = faces;
    report_progress(progress, "animation-space refinement", round + 1, rounds);
  }
  return model;
}

Result<AnimationSpaceModel> fit_sequence(const TriangleMesh& reference, const FrameMatrix& frames,
                                         const SequenceFitOptions& options, SequenceFitReport* report,
                                         std::vector<TransformList>* poses) {
  SequenceFitReport local;
  SequenceFitReport& out = report ? *report : local;
  auto skeleton = fit_sequence_skeleton(reference, frames, options, &out);
  if (!skeleton) return skeleton.error();
  const auto start = std::chrono::steady_clock::now();
  auto model = fit_sequence_model(reference, frames, *skeleton, options.fit, &out.fit);
  if (model && options.decompose && options.refinement_rounds > 0) {
    model = refine_animation_space(frames, std::move(*model), skeleton->training_poses, options.fit,
                                   options.refinement_rounds, &out.fit);
  }
  out.fit_seconds = seconds_since(start);
  if (poses) *poses = std::move(skeleton->training_poses);
  return model;
}

}  // namespace animspace::animation_space
