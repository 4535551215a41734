#include "core/pmsc/subspace.h"

#include <cassert>

namespace animspace::pmsc {

void Subspace::estimate(const Eigen::Ref<const Eigen::VectorXf>& key_values,
                        const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out) const {
  // Eq. 2 is the same least squares on the key rows of A for every kind: what a kind changes is
  // what A's columns are, which the projection precomputed at load already holds.
  estimate_coordinates(*model_, key_values, check_values, out);
}

Status Subspace::finish(const PoseEstimate& estimate, const FinishInput& input, PoseAnswer& out) const {
  const PmscModel& m = *model_;
  assert(input.full_points == nullptr || input.local);
  assert(!input.local || input.points != nullptr);
  out.local = LocalFailThrough();
  float* points = input.points;
  if (points == nullptr) {
    // Answered as coordinates: the verdict alone (eqs. 8–11), and f̂ only when the answer must be
    // points because f is at hand to blend with.
    const bool needs_full = judge(m, estimate, out.cached);
    const bool full_at_hand = input.full_values != nullptr || static_cast<bool>(input.full_calculation);
    if (!needs_full || !full_at_hand) {
      out.cached.full_evaluation_needed = needs_full;
      out.region_statuses = region_statuses(m, out.cached);
      out.points = nullptr;
      return Status::Ok();
    }
    out.cached.points.resize(m.mean.size());
    points = out.cached.points.data();
    const PoseEstimate* alone = &estimate;
    reconstruct({&alone, 1}, {&points, 1});
  }
  Eigen::Map<Eigen::VectorXf> answer(points, m.mean.size());
  if (input.local) {
    static const std::vector<int> kNone;
    ANIMSPACE_RETURN_IF_ERROR(finish_cached_local(m, estimate, answer,
                                                  input.full_points != nullptr ? *input.full_points : kNone,
                                                  input.full_values, input.partial_calculation, out.cached, out.local));
  } else {
    finish_cached(m, estimate, answer, input.full_values, input.full_calculation, out.cached);
  }
  out.region_statuses = region_statuses(m, out.cached);
  out.points = points;
  return Status::Ok();
}

Result<std::shared_ptr<const Subspace>> make_subspace(std::shared_ptr<const PmscModel> model) {
  assert(model != nullptr);
  // The registry of kinds: one line each.
  switch (model->subspace_kind) {
    case SubspaceKind::kLinear:
      return make_linear_subspace(std::move(model));
    case SubspaceKind::kArticulated:
      return make_articulated_subspace(std::move(model));
  }
  return make_error(ErrorCode::kInvalidArgument, "pmsc model: unknown subspace kind " +
                                                     std::to_string(static_cast<int>(model->subspace_kind)));
}

}  // namespace animspace::pmsc
