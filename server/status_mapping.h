// The one place where core errors become gRPC statuses (STYLE.md: errors cross from core to
// gRPC in exactly one mapping function).
#pragma once

#include <grpcpp/support/status.h>

#include "core/common/result.h"

namespace animspace::server {

grpc::StatusCode to_grpc_code(ErrorCode code);
grpc::Status to_grpc_status(const Error& error);

// Shorthands for the statuses the validation layer produces itself.
grpc::Status invalid_argument(const std::string& message);
grpc::Status not_found(const std::string& message);
grpc::Status unimplemented(const std::string& rpc, const std::string& why);

}  // namespace animspace::server
