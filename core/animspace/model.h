// An animation-space model and its evaluation (Merry 2007 ch. 3).
//
// Each vertex i has an animation-space position p (a 4b-vector, eq. 3.2) that is sparse: only
// the bones in its influence set have a non-zero 4-vector p_j. The posed vertex is
//   v = Σ_j G_j p_j                                                     (eq. 3.1)
// and on the hyperplane of interest the weight p̲ = Σ_j p̲_j (the sum of the 4th components)
// is 1, so v is a point. Linear blend skinning (SSD, eq. 2.2) is the special case
// p_j = w_j Ĝ_j⁻¹ v̂ (§3.1), see from_linear_blend in import.h.
//
// Layout: the influences of every vertex are stored back to back (compressed rows):
// vertex i owns influences offsets[i] … offsets[i+1]-1, each a bone index and a 4-vector, and
// the 4-vectors are the columns of a 4×I matrix. Evaluation streams through the three arrays
// once, in order, with each bone's 3×4 matrix G_j computed once per pose — the same work per
// influence as SSD (one 3×4 matrix–vector product), which is why animation space costs no more
// to evaluate (thesis Table 8.9).
//
// Normals (§3.5): each vertex may also carry a tangent plane, two animation-space vectors s
// and t (weight 0) with the same influence pattern; the posed normal is
// n = normalise(G s × G t). See tangents.h for how they are made (§4.3).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/skeleton.h"
#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::animation_space {

// 4 × I: column k is the 4-vector of influence k.
using InfluenceVectors = Eigen::Matrix<double, 4, Eigen::Dynamic>;

// Which bones influence each vertex, as compressed rows: vertex i's bones are
// bones[offsets[i] … offsets[i+1]-1], strictly increasing. Shared by models, fitting (§4.1.1)
// and linear-blend rigs.
struct InfluenceSets {
  std::vector<int32_t> offsets{0};  // V + 1 entries, offsets[0] == 0, non-decreasing
  std::vector<int32_t> bones;       // I entries

  int vertex_count() const { return static_cast<int>(offsets.size()) - 1; }
  int influence_count() const { return static_cast<int>(bones.size()); }
  int begin(int vertex) const { return offsets[static_cast<size_t>(vertex)]; }
  int end(int vertex) const { return offsets[static_cast<size_t>(vertex) + 1]; }
};

// Checks the compressed-row invariants, that every vertex has at least one influence and that
// bone indices lie in [0, bone_count). Errors: kInvalidArgument naming the vertex.
Status validate(const InfluenceSets& influences, int bone_count);

struct AnimationSpaceModel {
  Skeleton skeleton;
  FaceMatrix faces;          // #F × 3, may be empty (a point set)
  InfluenceSets influences;  // V vertices
  InfluenceVectors positions;  // 4 × I, p_j per influence
  // Optional tangent planes (§3.5): both empty, or both 4 × I with weight-0 columns.
  InfluenceVectors tangent_s;
  InfluenceVectors tangent_t;

  int vertex_count() const { return influences.vertex_count(); }
  int bone_count() const { return skeleton.bone_count(); }
  bool has_tangents() const { return tangent_s.cols() > 0; }
};

// Checks the skeleton, the influence sets, the sizes of every array, that all values are finite,
// that every vertex's weight p̲ is 1 (to `weight_tolerance`), that tangent vectors have weight 0,
// and that faces index existing vertices. Errors: kInvalidArgument naming the part and the vertex.
Status validate(const AnimationSpaceModel& model, double weight_tolerance = 1e-6);

// The weight p̲ of every vertex (V entries).
Eigen::VectorXd vertex_weights(const AnimationSpaceModel& model);

// Dense 4b-vector p of one vertex (for analysis and tests; the model itself stays sparse).
Eigen::VectorXd dense_position(const AnimationSpaceModel& model, int vertex);

// The per-pose matrices G_j, gathered once per evaluation. Full 4×4 (not 3×4) on purpose: a
// 4-row column is two SIMD packets, so G_j p_j vectorises; the 4th row costs nothing extra.
using PoseMatrices = TransformList;
PoseMatrices pose_matrices(const TransformList& globals);

// v = Σ_j G_j p_j for every vertex (eq. 3.1). `globals` holds one G_j per bone (validated by the
// caller, see validate_pose); `out` is resized to V × 3. Runs on all cores for large models.
void evaluate(const AnimationSpaceModel& model, const TransformList& globals, PointMatrix& out);

// The same for the listed vertices only (each in [0, V), asserted): `out` becomes |vertices| × 3,
// row j the posed vertices[j]. Each vertex is posed from its own influences alone (eq. 3.1), so a
// caller that needs a few vertices (local fail-through) pays for those only.
void evaluate_vertices(const AnimationSpaceModel& model, const TransformList& globals,
                       const std::vector<int>& vertices, PointMatrix& out);

// n = normalise(G s × G t) for every vertex (§3.5); requires has_tangents(). A vertex whose
// projected tangent plane collapses (|G s × G t| = 0, only in degenerate poses) gets n = 0.
void evaluate_normals(const AnimationSpaceModel& model, const TransformList& globals, PointMatrix& out);

// Linear blend skinning in its usual form, kept alongside as the baseline animation space is
// compared against (thesis Table 8.2 fits, Table 8.9 speed): v = Σ_j w_j (G_j Ĝ_j⁻¹) v̂.
struct LinearBlendModel {
  Skeleton skeleton;
  FaceMatrix faces;
  Eigen::Matrix<double, 3, Eigen::Dynamic> rest_points;  // 3 × V, v̂
  InfluenceSets influences;
  Eigen::VectorXd weights;  // I, w_j per influence; each vertex's weights sum to 1

  int vertex_count() const { return influences.vertex_count(); }
};

// Errors: kInvalidArgument (sizes, non-finite values, weights not summing to 1 within 1e-6).
Status validate(const LinearBlendModel& model);

// v = Σ_j w_j G_j Ĝ_j⁻¹ v̂ (eq. 2.2); the skinning matrices are formed once per pose.
void evaluate(const LinearBlendModel& model, const TransformList& globals, PointMatrix& out);

}  // namespace animspace::animation_space
