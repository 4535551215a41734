// Tangent planes of animation-space models, for normals (Merry 2007 §3.5, §4.3, Appendix A.1).
//
// Animation space has no normal vector, so each vertex carries a tangent plane spanned by two
// weight-0 animation-space vectors s, t with the vertex's influence pattern; the posed normal is
// n = normalise(G s × G t) (model.h, evaluate_normals). Two ways to make them:
//
// - tangent_planes_from_normals (§4.3.2, eq. 4.8): for a model imported from SSD, the rest
//   normal n̂ and orthonormal rest tangents ŝ, t̂ with ŝ × t̂ = n̂ give q_j = w_j Ĝ_j⁻¹ ŝ and
//   r_j = w_j Ĝ_j⁻¹ t̂, so G q = M ŝ and G r = M t̂ with M = Σ_j w_j G_j Ĝ_j⁻¹: the posed normal
//   is exactly SSD's n ∝ M⁻ᵀ n̂ (eq. 3.35) whenever det M > 0.
// - fit_tangent_planes (§4.3.1, Appendix A.1): for any model, the plane that best fits the
//   animation-space planes of the incident faces, the animation-space analogue of area-weighted
//   vertex normals.
//
// Orthonormality (§3.5 asks for it w.r.t. the L2,2 inner product, which needs pose statistics
// that a model alone does not carry): tangent_planes_from_normals makes s, t orthonormal in the
// rest-pose projection (Ĝ s = ŝ, Ĝ t = t̂); fit_tangent_planes makes them orthonormal in its
// fitting metric (see TangentFitOptions). Only the plane matters for the normal; the basis
// only affects conditioning.
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

// Tangent vectors for AnimationSpaceModel::tangent_s / tangent_t.
struct TangentPlanes {
  InfluenceVectors s;  // 4 × I, weight 0, columns aligned with model.positions
  InfluenceVectors t;  // 4 × I
  // Vertices with no usable plane (a zero rest normal; no non-degenerate incident face): their
  // s and t are 0, so evaluate_normals gives them n = 0.
  int64_t degenerate_vertices = 0;
};

// The rest pose of a model, v̂ = Σ_j Ĝ_j p_j per vertex (#V by 3, double precision).
Eigen::MatrixX3d rest_positions(const AnimationSpaceModel& model);

// Merry 2007 §4.3.2, eq. 4.8, with w_j = p̲_j (the weight of influence j, which is the SSD weight
// for a model from from_linear_blend). `rest_normals` is #V by 3 (any length; a zero row marks a
// vertex without a normal, counted in degenerate_vertices); e.g. geometry::area_weighted_normals of
// rest_positions, or the file's normals. ŝ is the unit vector n̂ × e for the coordinate axis e
// least aligned with n̂, and t̂ = n̂ × ŝ.
// Errors (kInvalidArgument): an invalid model (validate), a row count other than #V, a
// non-finite normal (naming the vertex).
Result<TangentPlanes> tangent_planes_from_normals(const AnimationSpaceModel& model, const Eigen::MatrixX3d& rest_normals);

struct TangentFitOptions {
  // The fitting metric (Appendix A.1.2's C, standing in for L2,2, which needs pose statistics):
  // per bone, the x, y, z components count as they are (model units) and the weight component
  // is multiplied by this length, because a weight moves the point by its bone's translation,
  // which changes from pose to pose by about a bone length. ≤ 0: a tenth of the bounding-box
  // diagonal of rest_positions (so the fit is unchanged when the model is scaled; measurements
  // in tangents.cpp).
  double weight_length_scale = 0;
};

// Merry 2007 §4.3.1 and Appendix A.1: for vertex i with incident faces (i, u, w) (rotated so
// that i comes first, orientation kept), the input planes are B_f = (p_u − p_i) ∧ (p_w − p_i),
// whose magnitudes weight them by area; the fitted plane a ∧ b maximises Σ_f ⟨B_f, a ∧ b⟩ over
// orthonormal a, b: the top singular pair of A = Σ_f (a_f b_fᵀ − b_f a_fᵀ), oriented so that
// aᵀ A b = σ > 0 (so G a × G b points the way the faces' normals do). In 3D this is the
// area-weighted normal.
// The model's tangents must use the vertex's own influence set, while a neighbour may have
// other bones. Its component p_m on such a bone m is re-expressed on i's bones as the rest
// point Ĝ_m p_m moving the way vertex i does, Σ_k w_k Ĝ_k⁻¹ Ĝ_m p_m (w_k = p̲_k of vertex i): a
// linear map that keeps weights and the rest-pose projection, so the edges stay weight-0 and
// the rest pose sees the true rest edges. It is exact where the neighbours' bones are i's. On
// the cow rig (7 poses, against the posed meshes' area-weighted normals) it is as good as the
// thesis's plain A.1 on the union of the neighbours' bones, which would need extra influences
// (99.9th percentile 3.9° for both), where simply dropping the other bones gives 30°.
// Errors (kInvalidArgument): an invalid model (validate), a model without faces.
Result<TangentPlanes> fit_tangent_planes(const AnimationSpaceModel& model, const TangentFitOptions& options = {});

}  // namespace animspace::animation_space
