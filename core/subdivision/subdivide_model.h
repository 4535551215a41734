// Subdivision in animation space (Merry 2007 §4.2): P' = P S.
//
// Subdivision makes every new vertex an affine combination of the control vertices, V' = S V,
// with S from the connectivity alone (subdivision_matrix.h). Posing is linear in the
// animation-space positions, v = G p (eq. 3.1), so subdividing P once, P' = P S, and posing it
// gives G P' = G P S = V S: exactly the posed mesh subdivided, in every pose — to rounding. The
// same holds for everything else that is linear in P: the limit tangents P U and P W become the
// tangent planes (§3.5), and G s × G t is then the limit surface's normal of the posed mesh.
//
// Linear blend skinning has no such property (the thesis's point): subdividing the rest pose and
// the weights separately (subdivide_linear_blend, kept as the baseline that shows it) poses
// Σ_j (S w)_j M_j (S v̂), a product of two subdivided quantities, where the posed mesh subdivided
// is S (Σ_j w_j M_j v̂).
//
// Influences: refined vertex i is influenced by every bone of every control vertex in its rows
// of S, U and W (the tangents' rows reach one ring further), with p'_j = Σ_c S_ic p_cj (zero where
// only a tangent needs bone j): the model's tangent planes must share the vertex's influence
// set (model.h), and this keeps them exact.
#pragma once

#include <string>
#include <vector>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/common/types.h"
#include "core/container/model_container.h"
#include "core/subdivision/subdivision_matrix.h"

namespace animspace::subdivision {

// The subdivided model: P' = P S on the union of the rows' bones, faces of the refined level
// (Catmull–Clark's quads split into two triangles each), tangent planes s = P U, t = P W when
// `matrices` has tangents (the input's own tangents are not used: they belong to the control
// mesh's facets, not to the limit surface). Same skeleton. `matrices` must have been built from
// `model`'s faces (column count asserted); `model` must be valid.
animation_space::AnimationSpaceModel apply(const animation_space::AnimationSpaceModel& model,
                                           const SubdivisionMatrices& matrices);

// The model's triangles refined by `options` (subdivision_matrices), then apply.
// Errors: as subdivision_matrices, and kInvalidArgument for an invalid model.
Result<animation_space::AnimationSpaceModel> subdivide(const animation_space::AnimationSpaceModel& model,
                                                       const SubdivisionOptions& options);

// S applied to per-vertex rows: `values` is #V_0 by D, the result #V_k by D (double inside).
FrameMatrix apply_rows(const SparseRows& S, const FrameMatrix& values);
PointMatrix apply_rows(const SparseRows& S, const PointMatrix& points);

// The non-exact alternative for linear blend skinning: rest points S v̂ and weights S w, the
// influence sets the union of the rows' bones, faces as in apply. Its posed mesh differs from the
// posed control mesh subdivided wherever neighbouring vertices move differently.
animation_space::LinearBlendModel subdivide_linear_blend(const animation_space::LinearBlendModel& model,
                                                         const SubdivisionMatrices& matrices);

// What subdivide_container did.
struct SubdivisionReport {
  Scheme scheme = Scheme::kLoop;
  int levels = 0;
  int control_vertices = 0;
  int control_influences = 0;
  int vertices = 0;
  int64_t faces = 0;  // triangles stored
  int influences = 0;
  bool metrics_kept = false;   // the stored metrics and bounding sphere carried over
  bool frames_subdivided = false;
  std::vector<std::string> dropped_sections;  // sections of the input not carried over
};

// A model file's animation-space model subdivided into a new model file of the same kind, that
// loads, serves, builds levels of detail and exports like any other. Carried over: the skeleton
// sections; the metrics (P = E[GᵀG], E[L_j] and B[L_j] depend on the skeleton's poses only) and the
// bounding sphere, which still holds in every pose when S has no negative entry (every refined
// vertex is then a convex combination of control vertices, so it stays in their hull); the
// training poses (sequence.bone_transforms) and the training frames subdivided (S applied to
// each frame's points, which is exactly the refined frame); metadata, with "generator",
// "description" and the subdivision.* keys set, and lod_levels and lod.* dropped. Everything else (levels of
// detail, anything tied to the control vertices) is dropped and listed in the report.
// Errors name `source`: a container of another kind (kFailedPrecondition), a model that does not
// load, and those of subdivision_matrices.
Result<container::ModelContainer> subdivide_container(const container::ModelContainer& in, const std::string& source,
                                                      const SubdivisionOptions& options,
                                                      SubdivisionReport* report = nullptr);

}  // namespace animspace::subdivision
