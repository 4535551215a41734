// A trained key-point subspace as a server serves it (issue #51): one immutable value per model
// version, its runtime built once when the model loads, behind the three calls every pose takes
// (Meyer & Anderson 2007 §2.4, runtime steps 2–5):
//
//   estimate     one pose's key (and check) values → its coordinates p, e_key, e_check, the
//                region errors, the rigid alignment (eq. 2, eq. 8); always one pose alone, so a
//                pose's verdict never depends on what it was evaluated with;
//   reconstruct  a batch of estimates → their points f̂ (eq. 1), the basis read once per batch;
//   finish       the verdict and the answer: status and α (eqs. 9–11), each region's verdict,
//                whole-pose or local fail-through through the caller's engine, the blend.
//
// What differs between kinds of subspace is how f̂ is made of p — the linear kind's dense
// product, the articulated kind's skinning (articulated.h) — so a kind is one implementation of
// `reconstruct` (and of `estimate` if it ever needs its own solve), registered once in
// make_subspace. The verdict's rules are the soft cache's, written once here for every kind.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/pmsc/local_fail_through.h"
#include "core/pmsc/pmsc_model.h"

namespace animspace::pmsc {

// What the caller has for finishing one pose besides its estimate.
struct FinishInput {
  // f̂ (N·D) from reconstruct(), overwritten with the answer in place; null when the pose is to
  // be answered as coordinates: then finish reconstructs f̂ itself only when the answer must be
  // points (a blend or miss whose f the caller brought or its engine computes).
  float* points = nullptr;
  // Local fail-through (local_fail_through.h): judge each region and compute or blend only the
  // points that need f. Needs `points`.
  bool local = false;
  // f the caller brought: the whole frame (N·D), or with `full_points` (sorted) the values of
  // those points only (|full_points|·D, local fail-through). Null: none.
  const Eigen::VectorXf* full_values = nullptr;
  const std::vector<int>* full_points = nullptr;
  // The caller's engine (fail-through, 2007 §2.4 step 5), called at most once and only when the
  // soft cache cannot answer alone and no f was brought: the whole frame, or some points on the
  // local path. Either may be empty (none).
  FullCalculation full_calculation;
  PartialFullCalculation partial_calculation;
};

// A finished pose: what a caller records and sends.
struct PoseAnswer {
  // Status, α, the errors, full_evaluation_needed, and the f an engine computed (the example a
  // miss log keeps). cached.points is used only when finish had to reconstruct f̂ itself.
  CachedPose cached;
  // Each region's verdict: its key-point error against its own thresholds, or the whole pose's
  // verdict where the regions were not calibrated for this estimate (a pose without check values
  // of a model with check points). Empty for a model without regions.
  std::vector<CacheStatus> region_statuses;
  // Local fail-through: the points that needed f and their α (empty otherwise).
  LocalFailThrough local;
  // The answer's N·D points (FinishInput::points, or cached.points), or null: answered as
  // coordinates (cached.full_evaluation_needed says whether the client must still compute f).
  const float* points = nullptr;
};

class Subspace {
 public:
  virtual ~Subspace() = default;
  Subspace(const Subspace&) = delete;
  Subspace& operator=(const Subspace&) = delete;

  const PmscModel& model() const { return *model_; }
  const std::shared_ptr<const PmscModel>& shared_model() const { return model_; }

  // Eq. 2 for one pose: `key_values` K·D in key order, `check_values` C·D in check order (size
  // 0: none). Values assumed finite (the caller validates input). Leaves out.points empty.
  virtual void estimate(const Eigen::Ref<const Eigen::VectorXf>& key_values,
                        const Eigen::Ref<const Eigen::VectorXf>& check_values, PoseEstimate& out) const;

  // Eq. 1 for a batch of estimates, each written to its destination (N·D floats; may be a
  // message's buffer), moved to the world for aligned models. A pose reconstructed alone or in
  // any batch differs only by float rounding (reconstruction_rounding_bound).
  virtual void reconstruct(std::span<const PoseEstimate* const> estimates,
                           std::span<float* const> destinations) const = 0;

  // The verdict of `estimate` and the answer (see FinishInput and PoseAnswer).
  // Errors: kInvalidArgument from check_covers when partial full values miss a point that needs f
  // (the caller names its field: full_points).
  Status finish(const PoseEstimate& estimate, const FinishInput& input, PoseAnswer& out) const;

 protected:
  explicit Subspace(std::shared_ptr<const PmscModel> model) : model_(std::move(model)) {}

 private:
  std::shared_ptr<const PmscModel> model_;
};

// The runtime of `model` (prepared: prepare_projection) for its kind, built once. Errors: a
// model its kind's runtime cannot serve (kInvalidArgument naming what, e.g. an articulated basis
// not of the skinning form).
Result<std::shared_ptr<const Subspace>> make_subspace(std::shared_ptr<const PmscModel> model);

// Each kind's runtime (one file each), registered in make_subspace.
Result<std::shared_ptr<const Subspace>> make_linear_subspace(std::shared_ptr<const PmscModel> model);
Result<std::shared_ptr<const Subspace>> make_articulated_subspace(std::shared_ptr<const PmscModel> model);

}  // namespace animspace::pmsc
