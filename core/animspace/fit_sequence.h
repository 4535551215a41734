// Any geometry cache → an animation-space model: the whole fitting pipeline of Merry 2007 §4.1
// with the user's hand-marked skeleton replaced by an automatic rigid segmentation.
//
// Phases: (1) segment the reference mesh into B near-rigid parts over the training frames
// (segmentation.h; what Dem Bones / SSDR does to initialise linear blend skinning); (2) fit the
// skeleton from each part's core vertices (§4.1.4: affine fit, polar decomposition, reflection
// fix, translation refit, joint placement with λ = 1e-3); (3) grow influence sets from the parts
// (§4.1.1); (4) solve the regularised least squares for every vertex at once (§4.1.2–4.1.3),
// either in full animation space or restricted to linear blend skinning weights (the baseline of
// thesis Table 8.2), on the same skeleton and influence sets.
//
// New frames that were not fitted get their skeleton pose the way §8.2 poses the gallop: each
// bone's rigid motion is fitted to its core vertices (estimate_pose).
#pragma once

#include <vector>

#include "core/animspace/fit.h"
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
  SkeletonFitReport skeleton;
  FitReport fit;
};

// What the pipeline found, kept so that new frames can be posed and other fits reuse it.
struct SequenceSkeleton {
  Skeleton skeleton;                               // B + 1 bones, Ĝ_j from §4.1.4
  std::vector<std::vector<int32_t>> core_vertices;  // per bone (empty for the root)
  std::vector<int32_t> labels;                      // #V: owning bone of each vertex
  InfluenceSets influences;
  std::vector<TransformList> training_poses;        // G^k of every training frame
};

// Phases 1–3 on `frames` (n × 3V, n ≥ 1), with `reference` (V points, faces) as the rest pose.
// Errors: the phases' own (kInvalidArgument naming the field for bad input).
Result<SequenceSkeleton> fit_sequence_skeleton(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceFitOptions& options, SequenceFitReport* report);

// Phase 4, full animation space.
Result<AnimationSpaceModel> fit_sequence_model(const TriangleMesh& reference, const FrameMatrix& frames,
                                               const SequenceSkeleton& skeleton, const FitOptions& options,
                                               FitReport* report);

// Phase 4 restricted to linear blend skinning weights (same skeleton, influences, regularisation).
Result<LinearBlendModel> fit_sequence_linear_blend(const TriangleMesh& reference, const FrameMatrix& frames,
                                                   const SequenceSkeleton& skeleton, const FitOptions& options,
                                                   FitReport* report);

// All four phases.
Result<AnimationSpaceModel> fit_sequence(const TriangleMesh& reference, const FrameMatrix& frames,
                                         const SequenceFitOptions& options, SequenceFitReport* report = nullptr);

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

// G_j for a frame (3V values, x0 y0 z0 x1 …) that was not fitted: M_j from the rigid fit of bone
// j's core vertices (reference → frame), G_j = M_j Ĝ_j; a bone without usable core vertices moves
// with its parent. `frame` must hold 3·#reference values (asserted).
TransformList estimate_pose(const SequenceSkeleton& skeleton, const PointMatrix& reference,
                            const Eigen::Ref<const Eigen::RowVectorXf>& frame);

}  // namespace animspace::animation_space
