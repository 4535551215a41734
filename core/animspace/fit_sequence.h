// Any geometry cache → an animation-space model: the whole fitting pipeline of Merry 2007 §4.1
// with the user's hand-marked skeleton replaced by an automatic rigid segmentation.
//
// Phases: (1) segment the reference mesh into B near-rigid parts over the training frames
// (segmentation.h; what Dem Bones / SSDR does to initialise linear blend skinning); (2) the
// skinning decomposition (skinning_decomposition.h: SSDR's alternation of per-frame rigid bone
// motions and sparse, non-negative, affine weights), whose weights are the linear blend model and
// whose supports are the influence sets; (3) the rest joints from the optimised motions (§4.1.4,
// eq. 4.6, λ = 1e-3) and a bone hierarchy from the parts' adjacency; (4) the animation-space
// refit (§4.1.2–4.1.3, edge regularisation) on those poses and influence sets, then
// refine_animation_space: rounds of {bone motions with the model fixed, model with the motions
// fixed}, each lowering the error.
//
// The first pass (SequenceFitOptions::decompose = false, the pipeline before the decomposition
// existed, kept as the baseline): (2) fit the skeleton from each part's core vertices (§4.1.4:
// affine fit, polar decomposition, reflection fix, translation refit), (3) grow influence sets
// from the parts (§4.1.1), (4) one least-squares solve, in animation space or restricted to
// unconstrained linear blend weights (thesis Table 8.2).
//
// Frames that were not fitted get their pose by solve_pose (bone_motions.h): the bones' motions
// solved with the model fixed, so that test error measures the model and not the pose estimate
// (the first pass used to pose them by §8.2's rigid fit of each bone's core vertices, which
// charged the model with the estimate's error).
#pragma once

#include <vector>

#include "core/animspace/fit.h"
#include "core/animspace/skinning_decomposition.h"
#include "core/animspace/model.h"
#include "core/animspace/segmentation.h"
#include "core/animspace/skeleton_fit.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

struct SequenceFitOptions {
  SegmentationOptions segmentation;  // bone_count = B parts (bones besides the root)
  InfluenceGrowthOptions influences;
  SkeletonFitOptions skeleton;       // a part too thin to fix a rotation moves with its parent
  FitOptions fit;                    // λ, δ (0.005: the thesis's horse), solver
  // Phase 2 as the alternating optimisation (true), or the first pass (false; see above).
  bool decompose = true;
  DecompositionOptions decomposition;  // K = decomposition.weights.max_influences
  // refine_animation_space rounds after the animation-space refit (decompose only). ≥ 0.
  int refinement_rounds = 3;
  SequenceFitOptions() {
    skeleton.inherit_undetermined_bones = true;
    fit.edge_regularisation = 0.005;
  }
};

struct SequenceFitReport {
  double segmentation_seconds = 0;
  double skeleton_seconds = 0;
  double fit_seconds = 0;
  double segmentation_rms = 0;  // rigid parts alone, model units
  SkeletonFitReport skeleton;            // first pass only
  DecompositionReport decomposition;     // decompose only
  FitReport fit;
};

// What the pipeline found, kept so that new frames can be posed and other fits reuse it.
struct SequenceSkeleton {
  Skeleton skeleton;                               // B + 1 bones, Ĝ_j from §4.1.4
  std::vector<int32_t> labels;                      // #V: owning bone of each vertex
  InfluenceSets influences;
  std::vector<TransformList> training_poses;        // G^k of every training frame
  // The decomposition's linear blend weights on `influences` (empty for the first pass).
  Eigen::VectorXd weights;
};

// Phases 1–3 on `frames` (n × 3V, n ≥ 1), with `reference` (V points, faces) as the rest pose.
// Progress: the decomposition's iterations. Errors: the phases' own (kInvalidArgument naming the
// field for bad input).
Result<SequenceSkeleton> fit_sequence_skeleton(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceFitOptions& options, SequenceFitReport* report,
                                               const ProgressCallback& progress = {});

// Phase 4, full animation space.
Result<AnimationSpaceModel> fit_sequence_model(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceSkeleton& skeleton, const FitOptions& options,
                                               FitReport* report);

// Phase 4 restricted to linear blend skinning weights: the decomposition's weights as they are,
// or for the first pass the least squares on the same skeleton, influences and regularisation.
Result<LinearBlendModel> fit_sequence_linear_blend(const TriangleMesh& reference, const FrameMatrix& frames,
                                                   const SequenceSkeleton& skeleton, const FitOptions& options,
                                                   FitReport* report);

// Alternates, `rounds` times, the bones' rigid motions in every training frame with the model
// fixed (bone_motions.h, two sweeps per round) and the model with the motions fixed
// (fit_animation_space with `options`); `poses` (G^k, one per frame) are updated in place. Each
// half lowers the regularised objective. `report` describes the last refit. Progress: stage
// "animation-space refinement", done = rounds. Errors: as fit_animation_space.
Result<AnimationSpaceModel> refine_animation_space(const FrameMatrix& frames, AnimationSpaceModel model,
                                                   std::vector<TransformList>& poses, const FitOptions& options,
                                                   int rounds, FitReport* report = nullptr,
                                                   const ProgressCallback& progress = {});

// All four phases; the training poses, when wanted, come back in `poses`.
Result<AnimationSpaceModel> fit_sequence(const TriangleMesh& reference, const FrameMatrix& frames,
                                         const SequenceFitOptions& options, SequenceFitReport* report = nullptr,
                                         std::vector<TransformList>* poses = nullptr);

// How far a model posed by `poses` is from `frames` (one row of 3V values per pose), over every
// vertex of every frame: RMS and largest vertex distance, model units. Used by `animspace fit`
// and the skinning benchmark, so both report the same statistic.
struct ReconstructionError {
  double rms = 0;
  double max = 0;
};
ReconstructionError reconstruction_error(const AnimationSpaceModel& model, const std::vector<TransformList>& poses,
                                         const FrameMatrix& frames);
ReconstructionError reconstruction_error(const LinearBlendModel& model, const std::vector<TransformList>& poses,
                                         const FrameMatrix& frames);

}  // namespace animspace::animation_space
