#include "server/status_mapping.h"

#include <gtest/gtest.h>

namespace animspace::server {
namespace {

TEST(StatusMapping, EveryCoreCodeHasOneGrpcCode) {
  const std::pair<ErrorCode, grpc::StatusCode> table[] = {
      {ErrorCode::kInvalidArgument, grpc::StatusCode::INVALID_ARGUMENT},
      {ErrorCode::kNotFound, grpc::StatusCode::NOT_FOUND},
      {ErrorCode::kDataLoss, grpc::StatusCode::DATA_LOSS},
      {ErrorCode::kFailedPrecondition, grpc::StatusCode::FAILED_PRECONDITION},
      {ErrorCode::kOutOfRange, grpc::StatusCode::OUT_OF_RANGE},
      {ErrorCode::kResourceExhausted, grpc::StatusCode::RESOURCE_EXHAUSTED},
      {ErrorCode::kUnimplemented, grpc::StatusCode::UNIMPLEMENTED},
      {ErrorCode::kIo, grpc::StatusCode::UNAVAILABLE},
      {ErrorCode::kInternal, grpc::StatusCode::INTERNAL},
  };
  for (const auto& [core, grpc_code] : table) {
    const auto status = to_grpc_status(Error{core, "field x: expected 3, got 4"});
    EXPECT_EQ(status.error_code(), grpc_code) << error_code_name(core);
    EXPECT_EQ(status.error_message(), "field x: expected 3, got 4");
  }
}

TEST(StatusMapping, ShorthandsCarryTheirCodeAndTheMessageAsGiven) {
  const std::pair<grpc::Status, grpc::StatusCode> table[] = {
      {invalid_argument("m"), grpc::StatusCode::INVALID_ARGUMENT},
      {not_found("m"), grpc::StatusCode::NOT_FOUND},
      {resource_exhausted("m"), grpc::StatusCode::RESOURCE_EXHAUSTED},
      {unavailable("m"), grpc::StatusCode::UNAVAILABLE},
  };
  for (const auto& [status, code] : table) {
    EXPECT_EQ(status.error_code(), code);
    EXPECT_EQ(status.error_message(), "m");
  }
}

}  // namespace
}  // namespace animspace::server
