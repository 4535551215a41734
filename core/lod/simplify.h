// Building the progressive mesh: memoryless appearance-preserving simplification in animation
// space with half-edge collapses (Merry 2007 §6.2, after Sander et al. 2001), combined with
// influence simplification (§6.3) in one cost-ordered sequence (§6.3.1).
//
// Cost of a half-edge collapse u → v (§6.2.1, memoryless form): u's one-ring is laid flat (a
// polar map whose lengths and angles are those of the L2,2 inner product, so the flattening is
// the animation-space surface's own), the old fan around u and the new fan around v are overlaid
// in it, and the deviation between the old and the new surface — linear inside every cell of
// the overlay — is measured at the cell corners: u itself and the crossings of old and new
// edges. The cost is the largest L2,2 norm of these deviations, i.e. the largest RMS distance
// (over the pose distribution P describes) by which the step moves a point of the surface.
// L2,2 replaces APS's Euclidean metric (§6.2.2); nothing else changes.
//
// Guards: OpenMesh's topological test (is_collapse_ok: no non-manifold edges, no fold-overs of
// the link), a boundary vertex only collapses along the boundary, the new fan must not fold in
// the flattening, and no face may turn by more than max_normal_deviation_degrees in the rest
// pose (normal-flip guard). With an atlas (SimplifyOptions::atlas), chart_atlas.h's border rules
// and the UV fold guard as well.
#pragma once

#include "core/animspace/metrics.h"
#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/common/progress.h"
#include "core/lod/chart_atlas.h"
#include "core/lod/progressive_mesh.h"

namespace animspace::lod {

// What orders the sequence.
//   kMemoryless  the thesis's cost (§6.2.1, §6.3.1): the largest deviation from the previous
//                mesh, and ‖s‖₂,₂ for a removal. The default: it measured best (below).
//   kQuadric     quadric error memory in normalised animation space (surface_quadrics.h): a
//                collapse costs (Q_u + Q_v)(y_v), an influence removal the rise of Q_v; both are
//                errors against the original surface, in one unit. With half-edge collapses
//                (vertices kept where they are) it measured worse than kMemoryless across poses
//                on every size of both bench characters (docs/BENCHMARKS.md, issue #26): it is
//                kept as an option and as the error that vertex placement will minimise.
// Either way each step records its memoryless deviation as Simplification::cost (levels.h's ε^l).
enum class CollapseCost { kMemoryless, kQuadric };

struct SimplifyOptions {
  CollapseCost cost = CollapseCost::kMemoryless;
  // Interleave influence removals with the edge collapses (§6.3.1); off gives pure APS.
  bool influence_simplification = true;
  // Normal-flip guard, in the rest pose.
  double max_normal_deviation_degrees = 90;
  // Influence removals cheaper than this fraction of the rest pose's bounding-box diagonal (far
  // below a pixel at any viewport size) are taken first, in cost order, without re-costing the
  // collapses around them: a rig's near-zero weights (cow-rig has 47 000 below 1e-6) would
  // otherwise re-cost every neighbourhood once per weight. 0 keeps the strict order.
  double negligible_cost = 1e-6;
  // Stop when this few vertices are left (the base mesh keeps at least this many, if topology
  // allows); influence removals continue until every vertex has one bone.
  int min_vertices = 4;
  // Vertices collapsed so far, of the input's count less min_vertices (core/common/progress.h).
  ProgressCallback progress = {};
  // The model's texture atlas, or null: with one, collapses keep its chart borders and no face
  // flips in UV (chart_atlas.h, Merry 2007 §5.1, §5.3). Not owned; read during the call only.
  const ChartAtlas* atlas = nullptr;
};

// The whole progressive mesh of `model` under the L2,2 metric of `metrics` (P = E[GᵀG]).
// The model needs faces; every vertex must be used by some face (the others cannot be reached by
// a collapse and are refused rather than silently kept).
// Errors: kInvalidArgument naming the part for an invalid model or metrics, metrics of another
// bone count, a model without faces, an unused vertex, or a non-manifold input (OpenMesh cannot
// represent it: the first offending face is named); ChartUvs::build's for an atlas that does not fit.
Result<ProgressiveMesh> build_progressive_mesh(const animation_space::AnimationSpaceModel& model,
                                               const animation_space::AnimationSpaceMetrics& metrics,
                                               const SimplifyOptions& options = {});

}  // namespace animspace::lod
