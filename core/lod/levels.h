// Discrete levels of detail cut from a progressive mesh, choosing one for a view, and geomorphs
// between neighbours (Merry 2007 §7.3).
//
// Level 0 is the input; level l+1 is the first state of the sequence with at most half the
// influences of level l (counted over live vertices), and so on down to the base mesh. The served
// levels (build_levels) are cut from a sequence of edge collapses alone, so the cuts halve the
// influences the collapses leave; each level's influences are then simplified after placement. Each level
// carries ε^l in model units. As cut, it is the largest cost of any step taken to reach it: a
// bound on the RMS deviation any one step introduced (memoryless: the steps' deviations are not
// summed, §8.5). fit_levels then places the vertices (level_fit.h) and makes ε^l a bound on the
// whole error: no input vertex is farther from the level, in RMS over the poses P describes.
//
// A viewer with pixel tolerance p, viewport width w pixels, horizontal field of view 2θ and the
// model's nearest bounding-sphere depth d may use geometric error ε = 2pd sinθ / w (eq. 7.2);
// the real-valued level l is found by linear interpolation between the two levels whose ε^l
// bracket ε, and the vertices are geomorphed (eq. 7.1) between ⌊l⌋ and ⌊l⌋+1.
#pragma once

#include <cstdint>
#include <vector>

#include "core/animspace/model.h"
#include "core/common/result.h"
#include "core/lod/chart_atlas.h"
#include "core/lod/level_fit.h"
#include "core/lod/progressive_mesh.h"
#include "core/lod/simplify.h"

namespace animspace::lod {

// Geomorph data from a level to the next coarser one (§7.3): for each vertex of the finer level,
// its position p^l and Δp = p^{l+1} − p^l on the union of both influence sets (aligned), where
// p^{l+1} is the position of the coarser vertex it was collapsed into.
struct Geomorph {
  animation_space::InfluenceSets aligned;      // finer level's vertex count
  animation_space::InfluenceVectors position;  // 4 × I_aligned, p^l
  animation_space::InfluenceVectors delta;     // 4 × I_aligned, Δp (weight 0)
};

struct LodLevel {
  animation_space::AnimationSpaceModel model;  // compact, vertices in input order
  std::vector<int32_t> vertex_ids;             // input vertex of each vertex of this level
  std::vector<int32_t> face_ids;               // input face of each face of this level (may be empty
                                               // for levels stored before face ids were)
  // With an atlas: the UV of each face corner (3·#F × 2, chart_atlas.h: a face keeps its input
  // face's chart, a corner the UV its input vertex has there); empty without one.
  CornerUvs corner_uvs;
  double epsilon = 0;                          // ε^l (0 for level 0)
  int64_t step_count = 0;                      // steps of the sequence applied
  // For each vertex of this level, the vertex of level l+1 it ends up in (empty for the last).
  std::vector<int32_t> coarser_vertex;
};

struct LodLevels {
  std::vector<LodLevel> levels;  // levels[0] is the input

  int count() const { return static_cast<int>(levels.size()); }
};

// Cuts the levels from `mesh`: each with at most half the influences of the previous one, until
// the base mesh or `max_levels` levels (≥ 1) in all.
LodLevels make_levels(const ProgressiveMesh& mesh, int max_levels = 16);

// The state after the first step at which at most `vertex_count` vertices are live (or the base
// mesh), as a compact model; `error` receives the largest cost so far, and `representative` the
// vertex of the result every input vertex was collapsed into (fit_level's argument), when not null.
animation_space::AnimationSpaceModel simplify_to_vertex_count(const ProgressiveMesh& mesh, int vertex_count,
                                                              std::vector<int32_t>* vertex_ids = nullptr,
                                                              double* error = nullptr,
                                                              std::vector<int32_t>* representative = nullptr);

// Places the vertices of every level l ≥ 1 against level 0 (the input) under P = E[GᵀG]
// (fit_level, which also simplifies influences when options ask), and sets ε^l to the largest fit
// bound of levels 1..l, so that ε^l never decreases and bounds the RMS-over-poses distance of
// every input vertex from level l. Returns each level's fit (level 0: zero error, its influences).
// Errors: fit_level's.
Result<std::vector<LevelFit>> fit_levels(LodLevels& lods, const Eigen::MatrixXd& P,
                                         const LevelFitOptions& options = {});

// How the served levels are made: one set of choices for the CLI, the demo and the bench.
struct LevelBuildOptions {
  // Influence simplification. With placement it runs after each level is placed, under the
  // exchange rule of level_fit.h, and the progressive mesh is edge collapses only: the combined
  // order of §6.3.1 costs a removal by how far the vertex moves, not by what the placed level
  // loses, and measured worse (docs/BENCHMARKS.md, issue #26). Without placement it is §6.3.1's.
  bool influence_simplification = true;
  bool placement = true;
  // level_fit.h's x: a level may lose this fraction of RMS per fraction of influences removed.
  double influence_exchange = 1;
  int max_levels = 16;  // ≥ 1
  double max_normal_deviation_degrees = 90;
  ProgressCallback progress = {};  // the progressive mesh's
  // The model's texture atlas, or null. With one, the progressive mesh keeps its chart borders
  // (chart_atlas.h, Merry 2007 §5.1) and every level carries corner_uvs. Not owned.
  const ChartAtlas* atlas = nullptr;
};

// The progressive mesh's and the placement's options for `options`.
SimplifyOptions progressive_mesh_options(const LevelBuildOptions& options);
LevelFitOptions level_fit_options(const LevelBuildOptions& options);

struct BuiltLevels {
  LodLevels lods;
  std::vector<LevelFit> fits;  // per level, when placed; empty otherwise
  size_t steps = 0;            // of the progressive mesh
};

// Progressive mesh, levels, placement and influence simplification, as `options` say; with an
// atlas, each level's corner UVs (level_corner_uvs).
// Errors: build_progressive_mesh's and fit_levels'.
Result<BuiltLevels> build_levels(const animation_space::AnimationSpaceModel& model,
                                 const animation_space::AnimationSpaceMetrics& metrics,
                                 const LevelBuildOptions& options = {});

// Δp and the aligned influences from level `level` to `level + 1` (asserted: level + 1 < count).
Geomorph geomorph(const LodLevels& lods, int level);

// The finer level's vertices moved a fraction t ∈ [0, 1] of the way to the coarser level
// (eq. 7.1): p = p^l + t Δp, on the finer level's connectivity.
animation_space::AnimationSpaceModel geomorphed_model(const LodLevels& lods, int level, double t);

// A viewer for eq. 7.2, named as the API names it (lod.proto, PixelTolerance): the screen-space
// error it tolerates and how far its camera is from the model.
struct PixelTolerance {
  double tolerance_px = 1;          // p, finite, > 0
  double viewport_width_px = 1024;  // w, finite, > 0
  double horizontal_fov_rad = 0.8;  // 2θ, in (0, π)
  double distance = 1;              // camera to the bounding sphere's centre, model units, finite, > 0
};

// The one check of a view (the daemon, the CLI and thumbnails all reach it through
// tolerated_error). Errors: kInvalidArgument "<field>: expected …, got …" for the first field out
// of range, the field named as above.
Status validate(const PixelTolerance& view);

// ε = 2pd sinθ / w (eq. 7.2), d = distance − bounding_radius the least depth of any point of the
// bounding sphere; 0 when the camera is inside or on the sphere (it sees full detail).
// Errors: validate's, also when the camera is inside.
Result<double> tolerated_error(const PixelTolerance& view, double bounding_radius);

// The real-valued level for a tolerated error ε ≥ 0: the largest l with interpolated ε^l ≤ ε
// (0 when ε < ε^1, the last level when ε ≥ its ε^l). Levels with equal ε^l: the coarser wins.
double select_level(const LodLevels& lods, double tolerated);

}  // namespace animspace::lod
