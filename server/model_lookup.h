// Resolving a request's ModelRef to a served model version: the name is checked first (so a
// path-like name is refused before it reaches the registry), then the registry is asked.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <grpcpp/support/status.h>

#include "animspace/v1/common.pb.h"
#include "server/model_registry.h"
#include "server/unary_call.h"

namespace animspace::server {

// OK and `out` set (and the call labelled with the model), or INVALID_ARGUMENT naming
// `field`.name / NOT_FOUND (for an unknown name, unknown_model's message) / FAILED_PRECONDITION.
// A version evicted under --memory-budget is loaded again, waited for until the earlier of
// `deadline` and the call's own; past it, UNAVAILABLE saying how long its last load took, and —
// for a unary call — that many milliseconds in the grpc-retry-pushback-ms trailer, which a client
// with a retry policy for UNAVAILABLE waits before it tries again (issue #53).
grpc::Status find_model(ModelRegistry& registry, const v1::ModelRef& ref, std::string_view field,
                        std::shared_ptr<const LoadedModel>& out, const CallControl* call = nullptr,
                        std::chrono::system_clock::time_point deadline = std::chrono::system_clock::time_point::max());

// NOT_FOUND for a model name the registry does not serve, with the nearest names and what it
// serves: "model 'crnae' is not loaded; did you mean 'crane'? models: arm, arm-pmsc, crane"
// (at most 20 names listed, then how many more).
grpc::Status unknown_model(const ModelRegistry& registry, std::string_view name);

// FAILED_PRECONDITION for a call the model's kind cannot serve:
// "model 'arm' version 2 is of kind animation_space: <reason>".
grpc::Status unsupported_by_kind(const LoadedModel& model, std::string_view reason);

// OK when `model` has a skeleton (an animation-space model, or a PMSC model with an
// animation-space posing engine), else the one refusal every skeleton-needing call gives:
// FAILED_PRECONDITION "model 'arm-pmsc' version 1 is of kind pmsc and has no skeleton: <reason>".
grpc::Status require_skeleton(const LoadedModel& model, std::string_view reason);

}  // namespace animspace::server
