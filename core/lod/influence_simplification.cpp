// Merry 2007, "Animation space" (PhD thesis), §6.3: influence simplification, solved with the
// constrained least squares of Appendix A.2.
#include "core/lod/influence_simplification.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <string>
#include <utility>


namespace animspace::lod {
namespace {

// Constraints per removal (§6.3 items 2 and 3): s_i = −p_i (four) and s̲ = Σ_j s_j,w = 0 (one).
constexpr int kConstraintCount = 5;
// A tangent t with ‖t‖²₂,₂ = tᵀP_I t at most this fraction of max|P_I|·‖t‖²₂ lies in P's null
// space to rounding (the rounding of tᵀP_I t itself is O(4k ε max|P_I| ‖t‖²), ~1e-14 of it): it has no
// direction to normalise, so Gram–Schmidt leaves it as it is. A genuine tangent has ‖t‖₂,₂ ≈ ‖t‖₂
// (P's vector blocks hold E[R̄ᵀR̄] = I), so this only fires when the translations in P exceed ~1e6.
constexpr double kDegenerateTangent = 1e-12;

std::string bone_list(const std::vector<int32_t>& bones) {
  std::string out = "{";
  for (size_t k = 0; k < bones.size(); ++k) {
    if (k > 0) out += ", ";
    out += std::to_string(bones[k]);
  }
  return out + "}";
}

// The 4k-vector of a 4 × k matrix, bone by bone (x, y, z, w of the first bone, then the next).
Eigen::VectorXd flatten(const animation_space::InfluenceVectors& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), v.size());
}

animation_space::InfluenceVectors unflatten(const Eigen::VectorXd& s) {
  return Eigen::Map<const animation_space::InfluenceVectors>(s.data(), 4, s.size() / 4);
}

// The correction that removes column `slot` from `v` (a position or a tangent): K b with
// b = (−v_slot, 0). The removed column is set to exactly −v_slot, which K b meets to rounding.
animation_space::InfluenceVectors correction_for(const Eigen::MatrixXd& K, const animation_space::InfluenceVectors& v,
                                                 int slot) {
  Eigen::VectorXd b = Eigen::VectorXd::Zero(kConstraintCount);
  b.head<4>() = -v.col(slot);
  animation_space::InfluenceVectors s = unflatten(K * b);
  s.col(slot) = -v.col(slot);
  return s;
}

void drop_column(animation_space::InfluenceVectors& v, int slot) {
  const Eigen::Index k = v.cols();
  animation_space::InfluenceVectors out(4, k - 1);
  out.leftCols(slot) = v.leftCols(slot);
  out.rightCols(k - 1 - slot) = v.rightCols(k - 1 - slot);
  v = std::move(out);
}

}  // namespace

InfluenceSimplifier::InfluenceSimplifier(Eigen::MatrixXd P) : P_(std::move(P)) {
  assert(P_.rows() == P_.cols() && P_.rows() % 4 == 0);
}

Eigen::MatrixXd InfluenceSimplifier::restricted_metric(const std::vector<int32_t>& bones) const {
  const auto k = static_cast<Eigen::Index>(bones.size());
  Eigen::MatrixXd PI(4 * k, 4 * k);
  for (Eigen::Index a = 0; a < k; ++a) {
    for (Eigen::Index c = 0; c < k; ++c) {
      PI.block<4, 4>(4 * a, 4 * c) = P_.block<4, 4>(4 * Eigen::Index{bones[static_cast<size_t>(a)]},
                                                      4 * Eigen::Index{bones[static_cast<size_t>(c)]});
    }
  }
  return PI;
}

Result<InfluenceSimplifier::SetQuadric*> InfluenceSimplifier::set_quadric(const std::vector<int32_t>& bones) {
  const auto found = sets_.find(bones);
  if (found != sets_.end()) return &found->second;
  SetQuadric set;
  set.PI = restricted_metric(bones);
  Result<DiagonalisedQuadric> quadric = diagonalise(set.PI);
  if (!quadric.ok()) {
    return make_error(ErrorCode::kInvalidArgument,
                      "influence simplification on bones " + bone_list(bones) + " failed: " + quadric.error().message);
  }
  set.quadric = std::move(*quadric);
  set.slots.resize(bones.size());
  return &sets_.emplace(bones, std::move(set)).first->second;
}

Result<const InfluenceSimplifier::SlotOperator*> InfluenceSimplifier::solution_operator(
    const std::vector<int32_t>& bones, int slot) {
  Result<SetQuadric*> set = set_quadric(bones);
  if (!set.ok()) return set.error();
  std::optional<SlotOperator>& cached = (*set)->slots[static_cast<size_t>(slot)];
  if (cached) return &*cached;

  // §6.3 with the bones outside I(p) eliminated (eq. 6.1): unknowns s_I (4k, bone by bone),
  // objective s_Iᵀ P_I s_I, and the five constraints s_slot = b_0..3, Σ_j s_j,w = b_4.
  const auto k = static_cast<Eigen::Index>(bones.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(kConstraintCount, 4 * k);
  A.block<4, 4>(0, 4 * Eigen::Index{slot}).setIdentity();
  for (Eigen::Index j = 0; j < k; ++j) A(4, 4 * j + 3) = 1.0;
  const Eigen::MatrixXd& PI = (*set)->PI;
  Result<Eigen::MatrixXd> K = constrained_least_squares_operator((*set)->quadric, A);
  if (!K.ok()) {
    return make_error(ErrorCode::kInvalidArgument, "influence simplification of bone " +
                                                        std::to_string(bones[static_cast<size_t>(slot)]) +
                                                        " from bones " + bone_list(bones) +
                                                        " failed: " + K.error().message);
  }
  // Depends only on (I(p), i) and P, so every vertex with these bones reuses it (§6.3).
  SlotOperator op;
  const Eigen::MatrixXd F = K->leftCols<4>();
  op.cost_form = F.transpose() * PI * F;
  op.K = std::move(*K);
  cached = std::move(op);
  ++operator_count_;
  return &*cached;
}

Status InfluenceSimplifier::check(const VertexState& state, int slot) const {
  const int k = state.influence_count();
  if (k < 2) {
    return make_error(ErrorCode::kFailedPrecondition,
                      "a vertex with " + std::to_string(k) + " influence(s) has none to remove, expected at least 2");
  }
  if (slot < 0 || slot >= k) {
    return make_error(ErrorCode::kOutOfRange, "slot " + std::to_string(slot) + " is outside the vertex's " +
                                                  std::to_string(k) + " influences " + bone_list(state.bones));
  }
  const int bone_count = static_cast<int>(P_.rows() / 4);
  for (const int32_t bone : state.bones) {
    if (bone < 0 || bone >= bone_count) {
      return make_error(ErrorCode::kInvalidArgument, "bone " + std::to_string(bone) + " of influences " +
                                                         bone_list(state.bones) + " is outside P's " +
                                                         std::to_string(bone_count) + " bones");
    }
  }
  assert(state.position.cols() == k);
  return Status::Ok();
}

InfluenceRemoval InfluenceSimplifier::make_removal(const VertexState& state, int slot, const SlotOperator& op) const {
  InfluenceRemoval out;
  out.slot = slot;
  out.bone = state.bones[static_cast<size_t>(slot)];
  out.correction = correction_for(op.K, state.position, slot);
  // ‖s‖₂,₂ by eq. 6.1; a rounding-negative square on P's null space reads as 0.
  const Eigen::Vector4d p = state.position.col(slot);
  out.cost = std::sqrt(std::max(0.0, p.dot(op.cost_form * p)));
  return out;
}

Result<InfluenceRemoval> InfluenceSimplifier::removal(const VertexState& state, int slot) {
  ANIMSPACE_RETURN_IF_ERROR(check(state, slot));
  Result<const SlotOperator*> op = solution_operator(state.bones, slot);
  if (!op.ok()) return op.error();
  return make_removal(state, slot, **op);
}

Result<InfluenceRemoval> InfluenceSimplifier::cheapest_removal(const VertexState& state) {
  ANIMSPACE_RETURN_IF_ERROR(check(state, 0));
  // Cost every slot from its 4 × 4 form; form the correction of the winner only.
  int best_slot = -1;
  double best_cost = 0;
  const SlotOperator* best_op = nullptr;
  for (int slot = 0; slot < state.influence_count(); ++slot) {
    Result<const SlotOperator*> op = solution_operator(state.bones, slot);
    if (!op.ok()) return op.error();
    const Eigen::Vector4d p = state.position.col(slot);
    const double cost = std::sqrt(std::max(0.0, p.dot((*op)->cost_form * p)));
    if (best_slot < 0 || cost < best_cost) {  // strict: ties keep the lower slot
      best_slot = slot;
      best_cost = cost;
      best_op = *op;
    }
  }
  return make_removal(state, best_slot, *best_op);
}

void InfluenceSimplifier::apply(const InfluenceRemoval& removal, VertexState& state) {
  const int slot = removal.slot;
  assert(slot >= 0 && slot < state.influence_count() && removal.correction.cols() == state.influence_count());
  assert(state.bones[static_cast<size_t>(slot)] == removal.bone);
  state.position += removal.correction;
  state.position.col(slot).setZero();  // exactly, whatever rounding the correction carried

  if (state.has_tangents()) {
    // The same bone leaves the tangents (§6.3, last paragraph), each moved by its own least
    // correction under the same constraints (their weight stays 0).
    Result<const SlotOperator*> op = solution_operator(state.bones, slot);
    assert(op.ok());  // removal() computed and cached it for this (bones, slot)
    if (op.ok()) {
      state.tangent_s += correction_for((*op)->K, state.tangent_s, slot);
      state.tangent_t += correction_for((*op)->K, state.tangent_t, slot);
      state.tangent_s.col(slot).setZero();
      state.tangent_t.col(slot).setZero();
    }
    // Gram–Schmidt in ⟨a, b⟩ = aᵀ P_I b restores an L2,2-orthonormal basis of the plane.
    const Eigen::MatrixXd& PI = (*set_quadric(state.bones))->PI;
    const double p_scale = PI.cwiseAbs().maxCoeff();
    auto inner = [&PI](const Eigen::VectorXd& a, const Eigen::VectorXd& c) { return a.dot(PI * c); };
    auto degenerate = [p_scale](const Eigen::VectorXd& a, double square) {
      return !(square > kDegenerateTangent * p_scale * a.squaredNorm());
    };
    Eigen::VectorXd s = flatten(state.tangent_s);
    Eigen::VectorXd t = flatten(state.tangent_t);
    const double ss = inner(s, s);
    if (!degenerate(s, ss)) {
      t -= (inner(t, s) / ss) * s;
      s /= std::sqrt(ss);
    }
    const double tt = inner(t, t);
    if (!degenerate(t, tt)) t /= std::sqrt(tt);
    state.tangent_s = unflatten(s);
    state.tangent_t = unflatten(t);
    drop_column(state.tangent_s, slot);
    drop_column(state.tangent_t, slot);
  }
  drop_column(state.position, slot);
  state.bones.erase(state.bones.begin() + slot);
}

}  // namespace animspace::lod
