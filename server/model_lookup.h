// Resolving a request's ModelRef to a served model version: the name is checked first (so a
// path-like name is refused before it reaches the registry), then the registry is asked.
#pragma once

#include <memory>
#include <string_view>

#include <grpcpp/support/status.h>

#include "animspace/v1/common.pb.h"
#include "server/model_registry.h"
#include "server/unary_call.h"

namespace animspace::server {

// OK and `out` set (and the call labelled with the model), or INVALID_ARGUMENT naming
// `field`.name / NOT_FOUND / FAILED_PRECONDITION.
grpc::Status find_model(const ModelRegistry& registry, const v1::ModelRef& ref, std::string_view field,
                        std::shared_ptr<const LoadedModel>& out, const CallControl* call = nullptr);

// FAILED_PRECONDITION for a call the model's kind cannot serve:
// "model 'arm' version 2 is of kind animation_space: <reason>".
grpc::Status unsupported_by_kind(const LoadedModel& model, std::string_view reason);

// OK when `model` has a skeleton (an animation-space model, or a PMSC model with an
// animation-space posing engine), else the one refusal every skeleton-needing call gives:
// FAILED_PRECONDITION "model 'arm-pmsc' version 1 is of kind pmsc and has no skeleton: <reason>".
grpc::Status require_skeleton(const LoadedModel& model, std::string_view reason);

}  // namespace animspace::server
