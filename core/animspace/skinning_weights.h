// Linear blend skinning weights for fixed bone motions: the weight half of skinning
// decomposition (SSDR, Le & Deng 2012 §4.1; the smoothness of Dem Bones, Le & Deng 2014).
//
// For vertex i with rest position v̂_i and candidate bones C, column j of A (3F × |C|) stacks
// M_j^k v̂_i over the frames k, and b stacks the captured v_i^k. The weights minimise
//   ‖A w − b‖² / (F s²) + μ ‖w − w̄_i‖²,    w ≥ 0, Σ w = 1, at most K non-zero,
// where s is the largest side of the rest pose's bounding box (so the data term is in the unit-box
// units of Merry 2007 §4.1.2 and μ means the same for any character), and w̄_i is the average of
// the current weights of i's mesh neighbours (Laplacian smoothing of the weight field: a weight
// the data leaves free follows the surface around it instead of fitting noise). The sparsity is
// SSDR's: solve over all candidates, keep the K largest, solve again over those.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/animspace/model.h"
#include "core/animspace/skeleton.h"
#include "core/common/types.h"
#include "core/geometry/edges.h"

namespace animspace::animation_space {

// argmin ½ wᵀ Q w − cᵀ w over the probability simplex {w ≥ 0, Σ w = 1} (Q: n × n symmetric
// positive semi-definite, n ≥ 1). A primal active-set method (Nocedal & Wright, Numerical
// Optimization, Algorithm 16.3) started at the best vertex of the simplex: each step solves the
// equality-constrained problem on the free set through its KKT system; exact up to rounding in at
// most a few times n steps. A singular Q (two bones moving alike) still gives a minimiser.
Eigen::VectorXd solve_simplex_qp(const Eigen::MatrixXd& Q, const Eigen::VectorXd& c);

struct WeightSolveOptions {
  int max_influences = 4;      // K ≥ 1
  double smoothness = 1e-4;    // μ ≥ 0, unit-box units (see the file comment)
};

// Per-vertex weights, compressed rows over bones (the root, bone 0, is never a candidate).
struct SkinningWeights {
  InfluenceSets influences;
  Eigen::VectorXd weights;  // I, ≥ 0, each vertex's sum 1
};

// Solves every vertex's weights (in parallel) given the motions. `rest`: 3 × V; `frames`: F
// matrices 3 × V; `motions`: F lists of rigid M_j^k (bone 0 = I); `candidates`: V sets of bones
// ≥ 1; `previous`: the current weights (for w̄, and kept when a vertex has no candidate);
// `neighbours`: mesh adjacency (vertex_adjacency). `scale`: s.
SkinningWeights solve_skinning_weights(const Eigen::Matrix3Xd& rest, const std::vector<Eigen::Matrix3Xd>& frames,
                                       const std::vector<TransformList>& motions, const InfluenceSets& candidates,
                                       const SkinningWeights& previous,
                                       const geometry::Adjacency& neighbours, double scale,
                                       const WeightSolveOptions& options);

}  // namespace animspace::animation_space
