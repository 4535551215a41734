// Texture stretch of a UV map (Sander, Snyder, Gortler & Hoppe 2001), measured on a surface given
// by its first fundamental form per triangle — one posed mesh, or the animation-space metric over
// the pose distribution P (Merry 2007 §5.3, eq. 5.8).
//
// For a triangle with UV corners u0, u1, u2 and surface edge vectors e1 = x1 − x0, e2 = x2 − x0,
// the map f from UV to the surface has the Jacobian J = [e1 e2] D with D = [u1−u0 u2−u0]⁻¹. Its
// singular values Γ ≥ γ are the largest and smallest stretch; Sander's L2 stretch of the
// triangle is √((Γ² + γ²)/2) = √(tr(JᵀJ)/2) and L∞ is Γ. JᵀJ = Dᵀ g D needs only the 2×2 Gram
// matrix g of the edges, so one code serves:
//   - a posed mesh: g = [e_i · e_k] in model space;
//   - animation space: g = [e_iᵀ P e_k] = E[(G e_i)·(G e_k)] with e_i the animation-space edge
//     (weight 0), so tr(JᵀJ) is the expected squared stretch over the poses: the L2 stretch
//     "across P" (§5.3: the thesis's (CJ)ᵀCJ = JᵀPJ).
// Over a surface, L2 = √(Σ A_T L2(T)² / Σ A_T) with A_T the surface area of triangle T
// (√det g / 2), multiplied by √(Σ a_T / Σ A_T) (a_T the UV area) so that the value no longer
// depends on the scale of the UVs and its lower bound is 1 (Sander 2001 §4's normalisation);
// L∞ = max_T Γ_T with the same factor.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"

namespace animspace::atlas {

// #F × 3: per face the Gram matrix of its edges e1 = x1 − x0, e2 = x2 − x0 as g11, g12, g22
// (squared model units).
using FaceMetrics = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// 3·#F × 2: row 3f + k is the UV of corner k of face f (seams are where a vertex's corners differ).
using CornerUvs = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

// g of every face of one posed mesh (double from float32 points).
FaceMetrics face_metrics(const PointMatrix& points, const FaceMatrix& faces);

// One triangle's stretch from its Gram matrix and UVs. uv_area is signed (> 0: not flipped);
// for uv_area ≤ 0 the stretch values are +∞.
struct TriangleStretch {
  double surface_area = 0;  // √det g / 2
  double uv_area = 0;       // signed
  double l2_squared = 0;    // (Γ² + γ²)/2, unnormalised
  double linf_squared = 0;  // Γ², unnormalised
};
TriangleStretch triangle_stretch(double g11, double g12, double g22, const Eigen::Vector2d& u0,
                                 const Eigen::Vector2d& u1, const Eigen::Vector2d& u2);

struct Stretch {
  double l2 = 0;            // normalised L2 stretch (≥ 1; 1 only for an isometry up to scale)
  double linf = 0;          // normalised L∞ stretch
  int64_t flipped = 0;      // faces with UV area ≤ 0 (not counted in l2/linf; a valid atlas has none)
};

// Stretch of `uvs` on the surface `metrics` (all faces, one atlas: the charts' relative scales
// count). Faces with UV area ≤ 0 are counted in `flipped` and left out of the sums.
Stretch stretch(const FaceMetrics& metrics, const CornerUvs& uvs);

// Stretch across poses by posing: each posed mesh's own normalised L2 and L∞, then
// l2 = √(mean over poses of L2²) and linf = max over poses of L∞. `posed` ≥ 1 meshes with the
// same vertex count, all posed from the model `faces` belong to.
Stretch stretch_across_poses(const std::vector<PointMatrix>& posed, const FaceMatrix& faces, const CornerUvs& uvs);

}  // namespace animspace::atlas
