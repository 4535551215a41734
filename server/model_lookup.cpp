#include "server/model_lookup.h"

#include <algorithm>
#include <utility>

#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {

grpc::Status find_model(const ModelRegistry& registry, const v1::ModelRef& ref, std::string_view field,
                        std::shared_ptr<const LoadedModel>& out, const CallControl* call) {
  if (grpc::Status valid = check_model_ref(ref, field); !valid.ok()) return valid;
  auto found = registry.find(ref.name(), ref.version());
  if (!found) {
    // A wrong version already lists the versions; a wrong name gets the names.
    if (found.error().code == ErrorCode::kNotFound && !registry.describe(ref.name())) {
      return unknown_model(registry, ref.name());
    }
    return to_grpc_status(found.error());
  }
  out = std::move(*found);
  if (call != nullptr) call->set_model(out->name);
  return grpc::Status::OK;
}

std::vector<std::string> nearest_names(std::string_view name, const std::vector<std::string>& candidates) {
  // Optimal string alignment distance, three rows of the dynamic programme.
  const auto distance = [](std::string_view a, std::string_view b) {
    std::vector<size_t> before(b.size() + 1), previous(b.size() + 1), current(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) previous[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
      current[0] = i;
      for (size_t j = 1; j <= b.size(); ++j) {
        const size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
        current[j] = std::min({previous[j] + 1, current[j - 1] + 1, previous[j - 1] + cost});
        if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
          current[j] = std::min(current[j], before[j - 2] + 1);
        }
      }
      std::swap(before, previous);
      std::swap(previous, current);
    }
    return previous[b.size()];
  };
  const size_t limit = std::max<size_t>(2, name.size() / 3);
  std::vector<std::pair<size_t, size_t>> near;  // (distance, index in candidates)
  for (size_t i = 0; i < candidates.size(); ++i) {
    const size_t d = distance(name, candidates[i]);
    if (d <= limit) near.emplace_back(d, i);
  }
  std::stable_sort(near.begin(), near.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  std::vector<std::string> out;
  for (size_t k = 0; k < near.size() && k < 3; ++k) out.push_back(candidates[near[k].second]);
  return out;
}

grpc::Status unknown_model(const ModelRegistry& registry, std::string_view name) {
  std::vector<std::string> served;
  for (const auto& entry : registry.list()) served.push_back(entry.name);
  std::string message = "model '" + std::string(name) + "' is not loaded";
  if (served.empty()) return not_found(message + "; the server serves no models");
  const std::vector<std::string> near = nearest_names(name, served);
  for (size_t k = 0; k < near.size(); ++k) {
    message += (k == 0 ? "; did you mean '" : k + 1 == near.size() ? " or '" : ", '") + near[k] + "'";
  }
  message += near.empty() ? "; models: " : "? models: ";
  constexpr size_t kListed = 20;
  for (size_t i = 0; i < served.size() && i < kListed; ++i) message += (i == 0 ? "" : ", ") + served[i];
  if (served.size() > kListed) message += ", … (" + std::to_string(served.size() - kListed) + " more)";
  return not_found(message);
}

grpc::Status unsupported_by_kind(const LoadedModel& model, std::string_view reason) {
  return {grpc::StatusCode::FAILED_PRECONDITION, "model '" + model.name + "' version " + std::to_string(model.version) +
                                                     " is of kind " + container::kind_name(model.info.kind) + ": " +
                                                     std::string(reason)};
}

grpc::Status require_skeleton(const LoadedModel& model, std::string_view reason) {
  if (model.animation_space) return grpc::Status::OK;
  return {grpc::StatusCode::FAILED_PRECONDITION, "model '" + model.name + "' version " + std::to_string(model.version) +
                                                     " is of kind " + container::kind_name(model.info.kind) +
                                                     " and has no skeleton: " + std::string(reason)};
}

}  // namespace animspace::server
