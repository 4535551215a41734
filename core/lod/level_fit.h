// Placing a level's vertices where they serve the original surface best, across poses (issue #26).
//
// A progressive mesh keeps every vertex where the input had it (half-edge collapses, §6.2.1), and
// an influence removal moves a vertex by the least L2,2 correction (§6.3) without asking where
// the surface would want it. Once a level is cut, its vertices can move: this is Hoppe et al.'s
// mesh optimisation (1993) — alternate the closest point of every input vertex on the level and
// the positions that minimise the distances to those points — carried out in normalised
// animation space (y = C p, C = P^½, Merry 2007 §3.3.2), where a squared distance is the mean
// squared distance across the poses P describes. While placed, each level vertex keeps its own
// bones and its weight Σ p̲ = 1; positions are solved one vertex at a
// time with its neighbours fixed (block Gauss–Seidel), a small dense system per vertex whose
// matrix is P restricted to the vertex's bones (CᵀC = P).
//
// The same closest points give the level an error bound: an input vertex p_o and its closest
// point p on the level (a fixed combination of the level's vertices, hence a point of the posed
// level in every pose) satisfy E_G‖G p_o − G p‖² = ‖C(p_o − p)‖², so the posed level is never
// farther from the posed input vertex, in RMS over the poses, than that distance. `bound` is its
// largest value over the input vertices.
//
// Influence simplification after placement (issue #26): a level vertex v carries the closest
// points of some input vertices o, each with its barycentric weight λ_o on v. With those points
// held, moving v by s changes the level's summed squared distance Σ_o ‖r_o‖² (r_o = y_o − its
// closest point) by exactly
//     h(s) = (Σ λ_o²) ‖s‖²₂,₂ − 2 ⟨C s, Σ λ_o r_o⟩,
// the same units as the fit itself: squared RMS-over-poses distance of the input surface, summed.
// Removing bone i from v moves it by §6.3's correction s (influence_simplification.h); its harm
// is h(s). Removals are taken cheapest harm first while
//   1. the level's RMS stays within (1 + x · removed / I₀) of its RMS before any removal, I₀ its
//      influences and x = influence_exchange: the level is never worse than edge collapses
//      alone by a larger fraction than the fraction of influences it saves (x = 1), and
//   2. no input vertex gets farther from the level than the largest distance before removals
//      (a removal that would do so is skipped).
// Then one more round of placement settles the surface on the remaining bones. Re-placement and
// the closest-point search only lower the summed distance, so rule 1 holds after it as well; the
// largest distance is measured again after it (`bound` is always the measured one).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/common/result.h"

namespace animspace::lod {

class InfluenceSimplifier;  // influence_simplification.h

struct LevelFitOptions {
  // Rounds of (closest points, then positions); 0 measures the bound without moving anything.
  int rounds = 3;
  // Gauss–Seidel sweeps over the vertices per round.
  int sweeps = 4;
  // Influence simplification after placement (above): the error a level may gain, as a fraction
  // of its RMS, per fraction of its influences removed. Negative: no influence is removed.
  double influence_exchange = -1;
};

struct LevelFit {
  // Over the input vertices, the L2,2 distance to the closest point found on the level (model
  // units): its largest value and its RMS. Both are upper bounds of the RMS-over-poses distance
  // from the posed input vertex to the posed level (for the poses P describes).
  double bound = 0;
  double rms = 0;
  // The level as placed with every influence it was cut with, before influence simplification:
  // its influences and its RMS (equal to the above when nothing was removed).
  int influences_before = 0;
  double rms_before = 0;
  int influences = 0;
};

// Moves the vertices of `level` (a simplification of `input` with the same skeleton) to fit the
// input surface under P = E[GᵀG] (4b × 4b). `representative[o]` names, for every input vertex o,
// the level vertex it was collapsed into (the level's own vertices name themselves): the closest
// point of o is searched on the faces around that vertex and its neighbours.
// `simplifier` (built on the same P), when given, is used for influence simplification and keeps
// its per-influence-set operators for the next call (fit_levels shares one across levels).
// Errors: kInvalidArgument naming the argument whose size does not fit, or a P that is not
// non-negative definite; InfluenceSimplifier's.
Result<LevelFit> fit_level(const animation_space::AnimationSpaceModel& input, const Eigen::MatrixXd& P,
                           const std::vector<int32_t>& representative, animation_space::AnimationSpaceModel& level,
                           const LevelFitOptions& options = {}, InfluenceSimplifier* simplifier = nullptr);

// The input surface in normalised animation space: y = C p of every vertex (n × V, n = 4b), made
// once for every level fitted to it (fit_levels) rather than once per level.
struct NormalisedInput {
  Eigen::MatrixXd P;
  Eigen::MatrixXd C;  // P^½
  Eigen::MatrixXd positions;
};
// Errors: kInvalidArgument for a P that is not 4b × 4b for the input's b bones or not
// non-negative definite.
Result<NormalisedInput> normalise_input(const animation_space::AnimationSpaceModel& input, const Eigen::MatrixXd& P);

// fit_level on an input normalised once; the level must have the input's bones.
Result<LevelFit> fit_level(const NormalisedInput& input, const std::vector<int32_t>& representative,
                           animation_space::AnimationSpaceModel& level, const LevelFitOptions& options = {},
                           InfluenceSimplifier* simplifier = nullptr);

}  // namespace animspace::lod
