// Skinning decomposition: a mesh sequence → rigid bone motions and sparse, non-negative, affine
// linear blend skinning weights, by alternating optimisation (SSDR: Le & Deng 2012, "Smooth
// Skinning Decomposition with Rigid Bones"; with the weight smoothness of Dem Bones, Le & Deng
// 2014).
//
// Starting from a rigid segmentation (segmentation.h: one bone per part, every vertex wholly on
// its part's bone, the parts' rigid motions), each iteration
//   1. solves every vertex's weights with the motions fixed (skinning_weights.h): at most K bones
//      among its candidates, w ≥ 0, Σ w = 1, pulled towards its neighbours' weights;
//   2. solves every bone's rigid motion in every frame with the weights fixed (bone_motions.h:
//      the closed-form weighted Procrustes of SSDR §4.2, bones in turn, frames in parallel);
// and stops at the first iteration that lowers the best RMS error so far by less than `tolerance`
// of it, returning the best iterate. Each half lowers its own objective; the error itself can rise
// a little near convergence (the smoothness pull, the truncation to K bones).
//
// Candidates of a vertex: the bones it currently has, the bone that dominates it and the bones
// whose parts lie within `candidate_hops` steps of that bone's part in the graph of touching parts
// (parts: vertices by dominant bone; touching: a mesh edge across). This keeps every weight local
// to the surface — a far bone that happens to fit the training frames is not a candidate — with
// no length or ring count that would depend on the mesh's resolution.
#pragma once

#include <cstdint>
#include <vector>

#include "core/animspace/skeleton.h"
#include "core/animspace/skinning_weights.h"
#include "core/common/progress.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

struct DecompositionOptions {
  WeightSolveOptions weights;
  // Upper bound on alternations; ≥ 0 (0 returns the segmentation as hard weights). The tolerance
  // normally ends the loop first (horse-gallop: 25–40 iterations).
  int iterations = 50;
  // Stop once an iteration lowers the best RMS error by less than this fraction. ≥ 0.
  double tolerance = 1e-3;
  // Candidate bones: parts within this many steps of the vertex's dominant part. ≥ 1. Measured
  // (docs/BENCHMARKS.md, skinning): 2 rather than 1 lowers the linear blend error on every split of
  // horse-gallop and crane, held-out blocks included (4–19%), and animation space's on crane; on
  // horse-gallop's held-out frames animation space loses 5–17%, as its four coordinates per
  // influence fit the farther bones to the training frames.
  int candidate_hops = 2;
  // Rounds over all bones of the motion update per iteration. ≥ 1.
  int motion_sweeps = 2;
};

struct DecompositionIteration {
  double rms = 0;      // over all vertices and frames, model units
  double seconds = 0;  // since the decomposition began
  double influences_per_vertex = 0;
};

struct DecompositionReport {
  double initial_rms = 0;  // the rigid segmentation's hard skinning
  std::vector<DecompositionIteration> iterations;
  bool converged = false;  // stopped by `tolerance`, not by `iterations`
  double seconds = 0;
};

struct SkinningDecomposition {
  SkinningWeights weights;              // bones 1 … b−1
  std::vector<TransformList> motions;   // frames × b rigid M_j^k, rest → frame k; M_0 = I
  double rms = 0;                       // RMS error of this (the best) iterate, model units
};

// `rest`: V × 3; `faces`: adjacency for smoothness and candidates (may be empty); `frames`: F × 3V;
// `labels`: V bones in [1, b); `initial_motions`: F lists of b rigid motions (bone 0 = I), e.g. a
// RigidSegmentation's transforms. Progress: stage "skinning decomposition", done = iterations.
// Errors: kInvalidArgument naming the field (sizes, labels, options).
Result<SkinningDecomposition> decompose_skinning(const PointMatrix& rest, const FaceMatrix& faces,
                                                 const FrameMatrix& frames, const std::vector<int32_t>& labels,
                                                 std::vector<TransformList> initial_motions,
                                                 const DecompositionOptions& options = {},
                                                 DecompositionReport* report = nullptr,
                                                 const ProgressCallback& progress = {});

}  // namespace animspace::animation_space
