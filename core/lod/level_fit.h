// Placing a level's vertices where they serve the original surface best, across poses (issue #26).
//
// A progressive mesh keeps every vertex where the input had it (half-edge collapses, §6.2.1), and
// an influence removal moves a vertex by the least L2,2 correction (§6.3) without asking where
// the surface would want it. Once a level is cut, its vertices can move: this is Hoppe et al.'s
// mesh optimisation (1993) — alternate the closest point of every input vertex on the level and
// the positions that minimise the distances to those points — carried out in normalised
// animation space (y = C p, C = P^½, Merry 2007 §3.3.2), where a squared distance is the mean
// squared distance across the poses P describes. Each level vertex keeps its own bones (its
// influence count does not change) and its weight Σ p̲ = 1; positions are solved one vertex at a
// time with its neighbours fixed (block Gauss–Seidel), a small dense system per vertex whose
// matrix is P restricted to the vertex's bones (CᵀC = P).
//
// The same closest points give the level an error bound: an input vertex p_o and its closest
// point p on the level (a fixed combination of the level's vertices, hence a point of the posed
// level in every pose) satisfy E_G‖G p_o − G p‖² = ‖C(p_o − p)‖², so the posed level is never
// farther from the posed input vertex, in RMS over the poses, than that distance. `bound` is its
// largest value over the input vertices.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/common/result.h"

namespace animspace::lod {

struct LevelFitOptions {
  // Rounds of (closest points, then positions); 0 measures the bound without moving anything.
  int rounds = 3;
  // Gauss–Seidel sweeps over the vertices per round.
  int sweeps = 4;
};

struct LevelFit {
  // Over the input vertices, the L2,2 distance to the closest point found on the level (model
  // units): its largest value and its RMS. Both are upper bounds of the RMS-over-poses distance
  // from the posed input vertex to the posed level (for the poses P describes).
  double bound = 0;
  double rms = 0;
};

// Moves the vertices of `level` (a simplification of `input` with the same skeleton) to fit the
// input surface under P = E[GᵀG] (4b × 4b). `representative[o]` names, for every input vertex o,
// the level vertex it was collapsed into (the level's own vertices name themselves): the closest
// point of o is searched on the faces around that vertex and its neighbours.
// Errors: kInvalidArgument naming the argument whose size does not fit, or a P that is not
// non-negative definite.
Result<LevelFit> fit_level(const animation_space::AnimationSpaceModel& input, const Eigen::MatrixXd& P,
                           const std::vector<int32_t>& representative, animation_space::AnimationSpaceModel& level,
                           const LevelFitOptions& options = {});

}  // namespace animspace::lod
