// Direct and one-bounce indirect diffuse illumination by final gather, on Embree 3.
//
// Meyer & Anderson 2007 §3.2 (Figs. 5, 10): the indirect illumination of a room lit by a point
// light, whose cost is nearly linear in the number of points — so computing it at the key points
// only and reconstructing the rest from the subspace is where the method saves most.
//
// Radiance leaving a point x with normal n and albedo ρ (all diffuse, per RGB channel):
//   direct     L_d(x) = ρ(x)/π · Σ_l I_l · max(0, n·ω_l) / r_l² · V(x, l)
//   indirect   L_i(x) = ρ(x)/π ∫_H L_d(y(x, ω)) cos θ dω
//                     ≈ ρ(x) · (1/S) Σ_s L_d(y(x, ω_s)),  ω_s cosine-distributed (pdf cos θ / π)
// where y(x, ω) is the first surface hit from x along ω (nothing when the ray leaves the scene,
// or when it hits a surface from its unlit side) and V is a shadow ray from y towards the light.
// L_d(y) at a hit is evaluated at the hit itself with the triangle's interpolated albedo and
// its geometric normal — or, with GatherOptions::direct_from_vertices (issue #38), interpolated
// from L_d at the hit triangle's vertices: L_d(y) ≈ (1 − u − v)·L_d(v₀) + u·L_d(v₁) + v·L_d(v₂).
//
// Determinism: the S directions of point i depend only on (seed, i, S, sampling) — a per-point
// rotation of one low-discrepancy set, or per-point jittered strata — never on which other points are computed, the thread count or the
// light. So a key point's value computed alone equals its value in the full gather bit for bit.
// With the same rays each time, the gather at a point is a smooth function of the light's
// position except where a shadow ray's visibility steps (a hit crossing a shadow's edge); a
// light_radius > 0 with several shadow rays turns each step into several smaller ones across a
// penumbra (issue #38: the steps are what the subspace cannot span).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "core/common/progress.h"
#include "core/common/result.h"
#include "core/common/types.h"
#include "core/illumination/surface.h"

namespace animspace::illumination {

// How a point's S hemisphere directions are drawn (issue #38 compares them by measurement).
enum class HemisphereSampling {
  // One Hammersley set of S points rotated per point (Cranley–Patterson): the original gather.
  kHammersley,
  // Jittered strata: S cells of equal area 1/S in m = ⌊√S⌋ rows (⌈S/m⌉ or ⌊S/m⌋ cells each, a
  // row's height in proportion), one uniform jitter per cell drawn from (seed, point, cell).
  kStratified,
};

struct GatherOptions {
  int samples = 64;        // S, hemisphere rays per point, ≥ 1
  uint64_t seed = 0;       // picks the per-point rotations / jitters
  HemisphereSampling sampling = HemisphereSampling::kHammersley;
  // The light's radius in metres (issue #38): 0 treats it as a point (one shadow ray per hit and
  // light: visibility is a step function of the light's position). > 0 treats each light as a
  // disc of this radius facing the hit, its visibility the fraction of `shadow_rays` rays to
  // points on the disc (stratified in radius, jittered per (seed, point, sample)) that reach it;
  // the irradiance still uses the centre's distance and angle. Used by the indirect gather only
  // (direct() stays a point light).
  double light_radius = 0;
  int shadow_rays = 1;     // per hit and light when light_radius > 0, ≥ 1
  // Issue #38: a hit reads the direct radiance L_d interpolated (barycentric) from its triangle's
  // three vertices, each computed once per light with one shadow ray, instead of tracing a shadow
  // ray from the hit itself to every light — the final gather of a two-pass renderer, which reads
  // a stored first pass at its hits. A ray then costs one cast instead of 1 + lights, and the
  // hits no longer depend on the light, so the training lights share them (indirect_frames):
  // ~1,000 rays per point, the count a converged gather needs, cost a training about what 64 cost
  // it with shadow rays. The price is L_d's variation inside one triangle (a shadow edge spread
  // over a triangle, the second-order part of cos θ / r²). Point lights only (light_radius 0).
  bool direct_from_vertices = false;
  // Issue #38: a vertex's value is the mean irradiance over its cell — the part of its triangles
  // where its barycentric weight is the largest, the area it stands for when the surface is drawn
  // — rather than the irradiance at the vertex itself: each ray leaves from its own point of the
  // cell (low-discrepancy, with the directions). A box filter over the sample's footprint, as a
  // pixel's value is over its own. It matters at contacts: a floor vertex on the line where a
  // wall stands sees, through half its hemisphere, the wall's first millimetres, so its value is
  // the value of one wall vertex and steps as a shadow edge crosses that vertex — a step in the
  // light's position that no subspace of a finite set of training lights represents (at 100k
  // points the largest errors of the subspace were all such vertices; docs/BENCHMARKS.md).
  bool cell_average = false;
  // Issue #38: with direct_from_vertices, the direct light stored at a vertex — what the hits
  // read — is the mean over its cell (the cell of cell_average) rather than the value at the
  // vertex: each light's shadow rays leave from this many points of the cell, and the vertex
  // keeps the fraction that arrive (the irradiance's cos θ / r² still the vertex's). 0: one
  // shadow ray from the vertex. A stored point value steps by its whole height when a shadow's
  // edge crosses the vertex, and a contact vertex (a block's side where it meets the floor) sees
  // the floor's first millimetres through half its hemisphere, so its gather steps with it: at
  // 20k points one 0.5 mm move of the light doubled such a vertex's value. The cell mean steps
  // by 1/this instead. Only vertices whose fan has both lit and shadowed corners cast them (a
  // straight shadow edge that crosses a cell separates the corners of its convex fan); the
  // others' cells are all lit or all dark. A vertex's points depend on (seed, vertex, count).
  int cell_shadow_rays = 0;
};

// Checks samples ≥ 1, shadow_rays ≥ 1, light_radius finite and ≥ 0, light_radius 0 with
// direct_from_vertices, and cell_shadow_rays ≥ 0 (> 0 only with direct_from_vertices). Error:
// kInvalidArgument naming the field.
Status check_gather_options(const GatherOptions& options);

// Checks 1 ≤ |lights| ≤ max_lights, finite positions, finite intensities ≥ 0. Errors:
// kInvalidArgument naming `name`[i].position / .intensity with the value.
Status check_lights(const std::vector<PointLight>& lights, const std::string& name, int max_lights = 64);

// The scene, built once (Embree BVH over the surface's triangles) and then read-only: every
// method is const and safe to call from many threads at once.
class IlluminationEngine {
 public:
  // Errors: those of check_surface; kInternal when Embree cannot build the scene.
  static Result<std::unique_ptr<IlluminationEngine>> create(SurfaceMesh surface);
  ~IlluminationEngine();
  IlluminationEngine(const IlluminationEngine&) = delete;
  IlluminationEngine& operator=(const IlluminationEngine&) = delete;

  const SurfaceMesh& surface() const { return surface_; }
  int point_count() const { return static_cast<int>(surface_.vertices.rows()); }

  // Direct radiance L_d at `points` (indices into the surface's vertices, any order, repeats
  // allowed), point-major RGB: out has 3·|points| values. Empty `points` is not "all": use
  // all_points(). One shadow ray per point and light; threads over points.
  void direct(const std::vector<PointLight>& lights, const std::vector<int>& points, Eigen::VectorXf& out) const;

  // One-bounce indirect radiance L_i at `points`, point-major RGB (3·|points| values).
  // S hemisphere rays per point plus one shadow ray per hit and light — or, with
  // direct_from_vertices, plus one per vertex of the surface and light (L_d at every vertex,
  // whatever the points); threads over points.
  void indirect(const std::vector<PointLight>& lights, const GatherOptions& options, const std::vector<int>& points,
                Eigen::VectorXf& out) const;

  // The direct radiance L_d at every vertex (point-major RGB, 3·N values) as a gather with
  // `options` and direct_from_vertices reads it at its hits: direct() at all_points(), or with
  // cell_shadow_rays > 0 each vertex's cell mean. Threads over the vertices.
  void vertex_direct(const std::vector<PointLight>& lights, const GatherOptions& options, Eigen::VectorXf& out) const;

  // One frame per light: frames.row(l) = indirect({lights[l]}, options, all_points()) bit for bit
  // (|lights| × 3N). With options.direct_from_vertices each point's rays are cast once for all the
  // lights and L_d is computed per light at every vertex; otherwise one gather per light.
  // Progress: stage "gather", lights done of |lights|.
  void indirect_frames(const std::vector<PointLight>& lights, const GatherOptions& options, FrameMatrix& frames,
                       const ProgressCallback& progress = {}) const;

  std::vector<int> all_points() const;

 private:
  explicit IlluminationEngine(SurfaceMesh surface);
  SurfaceMesh surface_;
  struct Embree;
  std::unique_ptr<Embree> embree_;
};

}  // namespace animspace::illumination
