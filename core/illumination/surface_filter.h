// A spatial filter of a gathered frame over the surface (issue #38 item 1).
//
// Meyer & Anderson 2007 §3.2 learn the indirect illumination from frames of a final gather; with a
// few dozen fixed rays per point each frame carries ~12% RMS noise (docs/BENCHMARKS.md, "Issue #38,
// first steps"), and a subspace trained on noisy frames spends its basis on the noise. Indirect
// irradiance varies slowly over a surface, so each point's irradiance is averaged over its
// neighbours on the surface — the classic irradiance filtering of final gathers — before training,
// and the server's full calculation on a miss applies the same filter so that it computes the
// function the subspace learned.
//
//   E_j      = L_j ⊘ ρ_j                         the gathered irradiance (per channel; L = ρ ⊙ E)
//   Ẽ_i      = Σ_j w_ij E_j / Σ_j w_ij            over neighbours j with n_i·n_j ≥ min_normal_cosine
//   L̃_i      = ρ_i ⊙ Ẽ_i
//   w_ij     = exp(−d_ij² / (2σ²)) − exp(−r² / (2σ²)),  d_ij ≤ r,  σ = r / 2
//   r        = √(k · A / (π N))                  A the surface's area, N its points
//
// Dividing by the albedo first keeps colour boundaries sharp (the irradiance is continuous across
// them, the radiance is not); the normal test keeps the two sides of a crease apart (the
// irradiance is not continuous there). The radius holds `neighbours` = k points on average at the
// surface's mean point density, so one setting means the same on any scene, size or tessellation
// of roughly uniform density (a strongly graded tessellation would want a local density; not
// needed by cornell_box). The Gaussian is shifted to reach 0 at r, so a neighbour at the edge of
// the disc weighs nothing and rounding cannot make a symmetric neighbourhood asymmetric. Its
// effective number of neighbours (Σw)² / Σw² on a plane is ≈ 0.60 k (∫w = 0.2970·πr²,
// ∫w² = 0.1467·πr²), and an uncorrelated noise's variance falls by that factor.
//
// Split as precompute (the neighbour lists and weights, once per surface) and apply (per frame):
// the precomputed struct is what a server caches beside the engine.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/illumination/surface.h"

namespace animspace::illumination {

struct SurfaceFilterOptions {
  // k, the expected number of neighbours within the radius at the mean density; 0 turns the
  // filter off (the gather's frames as they are). ≥ 0.
  int neighbours = 0;
  // Neighbours whose unit normals make a cosine below this with the point's are left out. In
  // (−1, 1]; 0.9 is about 26°.
  double min_normal_cosine = 0.9;
  // Local linear instead of local constant: Ẽ_i is the value at p_i of the plane (in the point's
  // tangent coordinates) fitted to the neighbours' E_j by weighted least squares. A mean over a
  // one-sided neighbourhood (at a face's border, by a crease) is biased by the irradiance's
  // gradient times the offset of the neighbours' centroid; the fit keeps linear fields exactly
  // wherever the neighbours span the plane, and equals the mean inside a symmetric neighbourhood.
  bool linear = false;
  bool enabled() const { return neighbours > 0; }
};

// Checks neighbours ≥ 0 and min_normal_cosine in (−1, 1]. Error: kInvalidArgument naming
// `name`.neighbours / `name`.min_normal_cosine and the value.
Status check_surface_filter_options(const SurfaceFilterOptions& options, const std::string& name);

// The precomputed filter: for point i, its neighbours indices[offsets[i] .. offsets[i+1]) (itself
// included) and their unnormalised weights w_ij. Empty (no points) when the filter is off.
struct SurfaceFilter {
  SurfaceFilterOptions options;
  double radius = 0;                // r, metres
  std::vector<int64_t> offsets;     // N + 1
  std::vector<int> indices;
  std::vector<float> weights;
  // With options.linear: each entry's tangent coordinates (p_j − p_i)·(t₁, t₂) / r.
  std::vector<Eigen::Vector2f> tangent;
  PointMatrix albedo;               // N × 3, the surface's ρ
  bool enabled() const { return !offsets.empty(); }
};

// Builds the neighbour lists over `surface` (a uniform grid of cells of side r, sorted by cell;
// deterministic whatever the thread count).
// Errors: check_surface_filter_options naming `name`; kInvalidArgument when the filter is on and
// the surface has no area.
Result<SurfaceFilter> surface_filter_precompute(const SurfaceMesh& surface, const SurfaceFilterOptions& options,
                                                const std::string& name = "filter");

// L̃ = the filtered frame (3·N values, point-major RGB) of `frame` (same shape). A channel whose
// albedo is 0 at a neighbour carries no irradiance estimate and is left out of that channel's
// average; a point whose own albedo is 0 in a channel gets 0 there. Accumulates in double. A
// linear fit whose neighbours do not span the plane (collinear, or one point) falls back to the
// mean.
// Threads over points. With the filter off, out = frame. `out` must not alias `frame`.
void surface_filter_apply(const SurfaceFilter& filter, const Eigen::VectorXf& frame, Eigen::VectorXf& out);

// The filtered values at a few points only (a PMSC model's key points): `support` is every point
// their filters read (sorted, unique; surface_filter_support), `values` the frame there (3·|support|),
// out the filtered values at `points` (3·|points|), equal bit for bit to those of
// surface_filter_apply on the whole frame. With the filter off, support = points' sorted set.
std::vector<int> surface_filter_support(const SurfaceFilter& filter, const std::vector<int>& points);
void surface_filter_apply_at(const SurfaceFilter& filter, const std::vector<int>& points,
                             const std::vector<int>& support, const Eigen::VectorXf& values, Eigen::VectorXf& out);

}  // namespace animspace::illumination
