#include "server/status_mapping.h"

namespace animspace::server {

grpc::StatusCode to_grpc_code(ErrorCode code) {
  switch (code) {
    case ErrorCode::kInvalidArgument: return grpc::StatusCode::INVALID_ARGUMENT;
    case ErrorCode::kNotFound: return grpc::StatusCode::NOT_FOUND;
    case ErrorCode::kDataLoss: return grpc::StatusCode::DATA_LOSS;
    case ErrorCode::kFailedPrecondition: return grpc::StatusCode::FAILED_PRECONDITION;
    case ErrorCode::kOutOfRange: return grpc::StatusCode::OUT_OF_RANGE;
    case ErrorCode::kResourceExhausted: return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case ErrorCode::kUnimplemented: return grpc::StatusCode::UNIMPLEMENTED;
    // An I/O failure on the server's own disk is not the caller's fault and may pass.
    case ErrorCode::kIo: return grpc::StatusCode::UNAVAILABLE;
    case ErrorCode::kInternal: return grpc::StatusCode::INTERNAL;
  }
  return grpc::StatusCode::UNKNOWN;
}

grpc::Status to_grpc_status(const Error& error) { return {to_grpc_code(error.code), error.message}; }

grpc::Status to_grpc_status(const Error& error, std::string_view field) {
  return {to_grpc_code(error.code), std::string(field) + ": " + error.message};
}

grpc::Status invalid_argument(const std::string& message) {
  return {grpc::StatusCode::INVALID_ARGUMENT, message};
}

grpc::Status not_found(const std::string& message) { return {grpc::StatusCode::NOT_FOUND, message}; }

grpc::Status resource_exhausted(const std::string& message) {
  return {grpc::StatusCode::RESOURCE_EXHAUSTED, message};
}

grpc::Status unavailable(const std::string& message) { return {grpc::StatusCode::UNAVAILABLE, message}; }

grpc::Status failed_precondition(const std::string& message) {
  return {grpc::StatusCode::FAILED_PRECONDITION, message};
}

grpc::Status unimplemented(const std::string& rpc, const std::string& why) {
  return {grpc::StatusCode::UNIMPLEMENTED, rpc + " is not implemented in this build: " + why};
}

grpc::Status unparsable(std::string_view what, std::string_view message_type) {
  return {grpc::StatusCode::INVALID_ARGUMENT,
          std::string(what) + " could not be parsed as " + std::string(message_type)};
}

}  // namespace animspace::server
