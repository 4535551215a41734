// Fitting animation-space (and, as the baseline, linear-blend) models to example poses
// (Merry 2007 §4.1; Table 8.2 compares the two parametrisations).
//
// Given n example meshes in correspondence, each with its skeleton pose G^k, every vertex's
// animation-space position p minimises
//   Σ_k ‖G^k p − v^k‖² + λ ‖p‖²                                         (eq. 4.2, 4.3)
// over the bones of its influence set (§4.1.1), subject to p̲ = 1 (§4.1.3: one weight is
// eliminated, so the result satisfies it exactly, not just approximately). With edge
// regularisation the vertices are coupled,
//   + δ Σ_edges (1/ℓ_e) ‖p_a − p_b‖²                                    (eq. 4.4)
// (a bone in only one of the two influence sets contributes its value against zero), and all
// vertices are solved together as one sparse system.
//
// Because λ and δ compare lengths with the scale-free weights, the problem is first moved into a
// normalised frame (§4.1.2): the bounding box of the example meshes becomes a box of largest side
// 1 centred at the origin (the thesis boxes the reference model; there is no distinguished
// reference here, and any similarity gives the same invariance). The similarity T is applied to
// poses as T G T⁻¹ and to positions as T p, so Σ_j G_j p_j is unchanged up to T; the result is
// mapped back with T⁻¹. λ and δ are therefore in normalised units and the fit is invariant to
// the scale and placement of the data.
//
// Precision: all least squares run in double. The normal equations are formed (their condition
// is the square of the example matrix's), which is harmless here: in the normalised frame the
// examples' rows are O(1) and λ > 0 bounds the smallest eigenvalue away from zero.
//
// There is no precompute/solve split: the system depends on the example meshes (edge lengths,
// normalisation), so nothing survives from one fit to the next; fitting is an offline step.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

// The training data: n ≥ 1 example meshes in correspondence and the pose of each.
struct FitExamples {
  // n poses; poses[k][j] = G^k_j, one finite affine transform per bone (bone j's frame →
  // model space). Need not come from the skeleton's hierarchy; G^k_0 is normally I.
  std::vector<TransformList> poses;
  // n × 3V, row k = example k's vertices x0 y0 z0 x1 … in model units.
  FrameMatrix meshes;

  int example_count() const { return static_cast<int>(poses.size()); }
};

// How the coupled (δ > 0) system is solved. Measured on a horse-sized synthetic problem (8432
// vertices, 25 bones, 24 examples, 25k edges, δ = 0.005) on 2 loaded cores: 2.5 influences per
// vertex (77k unknowns) CG 0.6–1 s vs direct 27 s; 4.4 influences (141k unknowns) CG 2.6–3.5 s
// vs direct 138 s; without edges (per-vertex solve) 0.03–0.07 s. CG and direct agree to 1e-7 at
// the default tolerance.
enum class FitSolver {
  // Preconditioned conjugate gradients on the reduced normal equations, block-Jacobi (one dense
  // block per vertex: its data, λ and the diagonal of the edge term), warm-started from the
  // block-Jacobi solution. Memory O(nonzeros); 150–250 iterations in the measurements above.
  kConjugateGradient,
  // Sparse Cholesky (Eigen SimplicialLLT, AMD ordering) of the same system: exact, no tolerance,
  // but non-supernodal and its fill grows fast with the number of vertices; for small problems
  // and as a reference.
  kDirect,
};

struct FitOptions {
  // λ of eq. 4.3, normalised units (see above), ≥ 0. Small enough not to bias well-determined
  // directions; it only pins directions the examples leave free. 0 is accepted when every vertex
  // is determined by the examples (else kFailedPrecondition). The thesis's vertex-regularised
  // horse uses 0.02 (Figure 8.3b).
  double vertex_regularisation = 1e-6;
  // δ of eq. 4.4, normalised units, ≥ 0; 0 turns the edge term off and every vertex is solved
  // independently (in parallel). The thesis uses 0.005 (horse), 0.01 (cat), 0.02 (arm). Needs
  // faces; with no faces there are no edges and δ has no effect.
  double edge_regularisation = 0;
  // Fit in the unit-box frame (§4.1.2). Off: λ and δ are in model units.
  bool normalise_scale = true;
  // Coupled solve only (δ > 0 and at least one edge).
  FitSolver solver = FitSolver::kConjugateGradient;
  double tolerance = 1e-10;     // kConjugateGradient: stop when ‖r − K y‖ ≤ tolerance · ‖r‖
  int max_iterations = 20000;   // kConjugateGradient: at most this many iterations
};

struct FitReport {
  int vertices = 0;
  int examples = 0;
  int edges = 0;             // edges in the eq. 4.4 term (0 when δ = 0)
  int64_t unknowns = 0;      // after eliminating one weight per vertex (§4.1.3)
  int64_t nonzeros = 0;      // of the coupled system's matrix (0 when solved per vertex)
  bool coupled = false;      // solved as one sparse system (δ > 0 with edges)
  int iterations = 0;        // conjugate-gradient iterations (0 for a direct or per-vertex solve)
  bool converged = true;     // false: conjugate gradients stopped at max_iterations
  double residual_rms = 0;   // √(mean over examples and vertices of ‖v_fit − v‖²), model units
  double residual_max = 0;   // largest ‖v_fit − v‖ over examples and vertices, model units
  double scale = 1;          // the normalisation's scale factor s (1 / largest box side)
  double seconds = 0;        // wall time of the whole fit
};

// Fits an animation-space model (§4.1). `examples`: n poses of b = skeleton.bone_count()
// transforms and an n × 3V mesh matrix; `faces`: #F × 3 over the V vertices (edges of eq. 4.4;
// may be empty); `influences`: V sets over bones 0 … b-1 (the root may or may not appear). The
// model gets `skeleton`, `faces` and `influences` unchanged; every vertex has p̲ = 1 exactly
// (to rounding) and no bone outside its set.
// Errors: kInvalidArgument naming the input (sizes, NaN/Inf, a pose, a face index, an edge whose
// average length is 0, negative λ or δ, all example points coincident under normalisation);
// kFailedPrecondition when the system is singular (λ = 0 and a vertex the examples do not
// determine).
Result<AnimationSpaceModel> fit_animation_space(const Skeleton& skeleton, const FitExamples& examples,
                                                const FaceMatrix& faces, const InfluenceSets& influences,
                                                const FitOptions& options = {}, FitReport* report = nullptr);

// Fits linear-blend (SSD) weights with the same objective (the baseline of Table 8.2): the rest
// mesh v̂ and rest transforms Ĝ are given, and each influence's 4-vector is restricted to
// p_j = w_j Ĝ_j⁻¹ v̂ (§3.1), one scalar unknown w_j per influence, Σ_j w_j = 1 by the same
// elimination. `rest_points`: V × 3, model units. Weights are not constrained to be ≥ 0.
// Errors: as fit_animation_space, plus kInvalidArgument for an invalid skeleton or rest points.
Result<LinearBlendModel> fit_linear_blend(const Skeleton& skeleton, const PointMatrix& rest_points,
                                          const FitExamples& examples, const FaceMatrix& faces,
                                          const InfluenceSets& influences, const FitOptions& options = {},
                                          FitReport* report = nullptr);

// Influence sets grown from a rigid segmentation (§4.1.1: sets are "pre-defined"; this derives
// them from per-vertex bone labels instead of painting).
struct InfluenceGrowthOptions {
  // A vertex is influenced by the bones owning the vertices within this many edges (0: only its
  // own bone). ≥ 0.
  int rings = 1;
  // Also add the parent of the vertex's own bone (none for the root): the skin around a joint
  // moves with both bones even where the segmentation boundary is not yet reached.
  bool include_parent = true;
  // Cap per vertex, ≥ 1. When more bones qualify, keep in this order: own bone, its parent, then
  // bones by ring distance, then by how many vertices within `rings` they own (more first), then
  // by index.
  int max_influences = 4;
};

// `owning_bone`: V labels in [0, b) with b = skeleton.bone_count(); `faces`: #F × 3 over those V
// vertices (adjacency; may be empty, then every vertex gets its own bone and parent only).
// Returns V sets, bones strictly increasing. Errors: kInvalidArgument naming the vertex, face or
// option.
Result<InfluenceSets> grow_influence_sets(const Skeleton& skeleton, const std::vector<int32_t>& owning_bone,
                                          const FaceMatrix& faces, const InfluenceGrowthOptions& options = {});


}  // namespace animspace::animation_space
