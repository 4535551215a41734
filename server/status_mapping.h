// The one place where core errors become gRPC statuses (STYLE.md: errors cross from core to
// gRPC in exactly one mapping function).
#pragma once

#include <string>
#include <string_view>

#include <grpcpp/support/status.h>

#include "core/common/result.h"

namespace animspace::server {

grpc::StatusCode to_grpc_code(ErrorCode code);
grpc::Status to_grpc_status(const Error& error);
// A core error about the request value named `field`: its code, the message after "<field>: ".
grpc::Status to_grpc_status(const Error& error, std::string_view field);

// Shorthands for the statuses the server produces itself (validation, its own limits, what this
// server cannot do at all).
grpc::Status invalid_argument(const std::string& message);
grpc::Status not_found(const std::string& message);
// Over a limit of this server (--max-message-bytes, a queue's depth, a batch size).
grpc::Status resource_exhausted(const std::string& message);
// Not possible on this server now but maybe elsewhere or later (no renderer, shutting down).
grpc::Status unavailable(const std::string& message);
grpc::Status unimplemented(const std::string& rpc, const std::string& why);
// Valid, but the model's state does not allow it (a retrain with nothing new to train on).
grpc::Status failed_precondition(const std::string& message);
// Bytes that are not the method's message: "<what> could not be parsed as animspace.v1.<Type>".
grpc::Status unparsable(std::string_view what, std::string_view message_type);

}  // namespace animspace::server
