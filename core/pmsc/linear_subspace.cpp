// The linear kind (Meyer & Anderson 2007 §2.1): A is principal components of the training frames,
// and f̂ = mean + A p is one dense product — batched, the basis read once per batch.
#include "core/pmsc/subspace.h"

namespace animspace::pmsc {
namespace {

class LinearSubspace final : public Subspace {
 public:
  explicit LinearSubspace(std::shared_ptr<const PmscModel> model) : Subspace(std::move(model)) {}

  void reconstruct(std::span<const PoseEstimate* const> estimates,
                   std::span<float* const> destinations) const override {
    pmsc::reconstruct(model(), estimates, destinations);
  }
};

}  // namespace

Result<std::shared_ptr<const Subspace>> make_linear_subspace(std::shared_ptr<const PmscModel> model) {
  return std::shared_ptr<const Subspace>(std::make_shared<LinearSubspace>(std::move(model)));
}

}  // namespace animspace::pmsc
