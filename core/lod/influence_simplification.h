// Influence simplification (Merry 2007 §6.3): removing one bone's influence from a vertex while
// moving it as little as possible in the L2,2 metric.
//
// To remove bone i from p, add the correction s that
//   1. lives on p's own bones (s_j = 0 for j ∉ I(p)),
//   2. cancels bone i (s_i = −p_i),
//   3. is a vector (s̲ = 0, so p + s keeps weight 1),
//   4. minimises ‖s‖²₂,₂ = sᵀPs, restricted to I(p) (eq. 6.1),
//   5. and of those minimisers has the least Euclidean norm,
// a constrained least-squares problem with 5 constraints in 4|I(p)| unknowns (Appendix A.2).
// The cost of the removal is ‖s‖₂,₂, the RMS distance the vertex moves over the pose
// distribution — the same units as an edge collapse's cost, so both share one queue (§6.3.1).
// The cheapest bone is the one removed.
//
// The tangent plane (§3.5) loses the same bone: s and t each get the correction with the same
// constraints (their weight stays 0), then are made L2,2-orthonormal again by Gram–Schmidt
// (§6.3, last paragraph); the position alone decides which bone goes.
//
// Because the solution operator depends only on (I(p), i) and P (constrained_least_squares.h),
// it is computed once per pair and cached. Successive removals work from the previous position,
// not the original: Appendix B.1 proves this gives the same result.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/lod/constrained_least_squares.h"
#include "core/lod/vertex_state.h"

namespace animspace::lod {

struct InfluenceRemoval {
  int slot = -1;        // index into VertexState::bones of the bone removed
  int32_t bone = -1;    // that bone
  double cost = 0;      // ‖s‖₂,₂ ≥ 0
  animation_space::InfluenceVectors correction;  // s on the vertex's bones, 4 × k (column `slot` = −p_i)
};

class InfluenceSimplifier {
 public:
  // P = E[GᵀG] of the model (4b × 4b, symmetric non-negative definite: asserted square with a
  // multiple-of-4 size; validate the metrics before).
  explicit InfluenceSimplifier(Eigen::MatrixXd P);

  // The cheapest removal for `state` (≥ 2 influences). Ties go to the lower slot.
  // Errors: kFailedPrecondition for a vertex with fewer than 2 influences; kInvalidArgument for a
  // bone outside P or a solver failure (naming the bones).
  Result<InfluenceRemoval> cheapest_removal(const VertexState& state);

  // The removal of one given slot (same errors, plus a slot out of range).
  Result<InfluenceRemoval> removal(const VertexState& state, int slot);

  // Applies `removal` (from cheapest_removal/removal on this same state): p ← p + s, tangents
  // corrected and re-orthonormalised, and the bone dropped from every array.
  void apply(const InfluenceRemoval& removal, VertexState& state);

  // Number of distinct (influence set, bone) operators computed so far (for tests and benches).
  size_t cached_operator_count() const { return operator_count_; }

 private:
  // K for (bones, slot), and the 4 × 4 form Fᵀ P_I F of its first four columns F: with
  // b = (−p_slot, 0), ‖K b‖²₂,₂ = p_slotᵀ (Fᵀ P_I F) p_slot, so a removal is costed without
  // forming its correction.
  struct SlotOperator {
    Eigen::MatrixXd K;
    Eigen::Matrix4d cost_form;
  };
  // Computed on first use and cached; an error if the solver rejects it.
  Result<const SlotOperator*> solution_operator(const std::vector<int32_t>& bones, int slot);
  // Checks the vertex and the slot (the errors of removal()).
  Status check(const VertexState& state, int slot) const;
  // The removal of `slot` once its operator is known.
  InfluenceRemoval make_removal(const VertexState& state, int slot, const SlotOperator& op) const;
  // P restricted to `bones` (P_I of eq. 6.1), 4k × 4k.
  Eigen::MatrixXd restricted_metric(const std::vector<int32_t>& bones) const;

  // P_I and its diagonalisation per influence set, shared by every bone removed from the set,
  // and the operators of the slots used so far.
  struct SetQuadric {
    Eigen::MatrixXd PI;
    DiagonalisedQuadric quadric;
    std::vector<std::optional<SlotOperator>> slots;  // one per bone of the set
  };
  Result<SetQuadric*> set_quadric(const std::vector<int32_t>& bones);

  Eigen::MatrixXd P_;
  std::map<std::vector<int32_t>, SetQuadric> sets_;
  size_t operator_count_ = 0;
};

}  // namespace animspace::lod
