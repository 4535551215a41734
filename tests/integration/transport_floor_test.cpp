// animspace-transport-floor (server/transport_floor/), started as animspace-bench starts it and
// seen only through the protocol: its canned answers must parse as the daemon's do and be the
// size of an N-point, D-channel answer, or the bench's floor rows measure a different transport.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "harness/daemon_process.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

constexpr int kPoints = 5, kChannels = 3;

class TransportFloorTest : public ::testing::Test {
 protected:
  std::unique_ptr<v1::PoseService::Stub> start(const std::string& bytes_per_value) {
    floor_ = std::make_unique<harness::DaemonProcess>(
        harness::transport_floor_binary(),
        std::vector<std::string>{"--point-count", std::to_string(kPoints), "--channel-count", std::to_string(kChannels),
                                 "--bytes-per-value", bytes_per_value},
        dir_.path());
    return v1::PoseService::NewStub(grpc::CreateChannel(floor_->address(), grpc::InsecureChannelCredentials()));
  }

  testing::TempDir dir_;
  std::unique_ptr<harness::DaemonProcess> floor_;
};

v1::EvaluateKeyPointsRequest request_of(int poses, bool omit_points) {
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name("any");
  for (int i = 0; i < poses; ++i) request.add_poses()->mutable_key_values()->set_point_count(1);
  request.set_omit_points(omit_points);
  return request;
}

void expect_canned(const v1::PoseResult& result, size_t point_bytes) {
  EXPECT_EQ(result.status(), v1::CACHE_STATUS_HIT);
  EXPECT_EQ(result.points().point_count(), static_cast<uint32_t>(kPoints));
  EXPECT_EQ(result.points().channel_count(), static_cast<uint32_t>(kChannels));
  EXPECT_EQ(result.points().data().size(), point_bytes);
}

TEST_F(TransportFloorTest, UnaryAnswersEveryPoseWithNTimesDFloats) {
  auto stub = start("4");
  for (int poses : {1, 3}) {
    grpc::ClientContext context;
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = stub->EvaluateKeyPoints(&context, request_of(poses, false), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    ASSERT_EQ(response.results_size(), poses);
    for (const v1::PoseResult& result : response.results()) expect_canned(result, 4 * kPoints * kChannels);
  }
  grpc::ClientContext context;
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(stub->EvaluateKeyPoints(&context, request_of(1, true), &response).ok());
  ASSERT_EQ(response.results_size(), 1);
  EXPECT_TRUE(response.results(0).points().data().empty());
}

TEST_F(TransportFloorTest, UnaryRefusesAnEmptyBatchAsTheDaemonDoes) {
  auto stub = start("4");
  grpc::ClientContext context;
  v1::EvaluateKeyPointsResponse response;
  EXPECT_EQ(stub->EvaluateKeyPoints(&context, request_of(0, false), &response).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(TransportFloorTest, StreamAnswersEveryFrameInOrderWithItsSequence) {
  auto stub = start("4");
  grpc::ClientContext context;
  auto call = stub->StreamKeyPoints(&context);
  // Arbitrary, non-consecutive sequence numbers (0 included: proto3 does not encode it).
  const std::vector<uint64_t> sequences{7, 0, 3, 1ull << 40, 12, 5};
  for (size_t i = 0; i < sequences.size(); ++i) {
    v1::KeyPointFrame frame;
    if (i == 0) frame.mutable_model()->set_name("any");
    frame.set_sequence(sequences[i]);
    ASSERT_TRUE(call->Write(frame));
  }
  call->WritesDone();
  std::vector<uint64_t> received;
  v1::PoseResult result;
  while (call->Read(&result)) {
    expect_canned(result, 4 * kPoints * kChannels);
    received.push_back(result.sequence());
  }
  const grpc::Status status = call->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(received, sequences);
}

TEST_F(TransportFloorTest, SixteenBitValuesHalveThePoints) {
  auto stub = start("2");
  grpc::ClientContext context;
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(stub->EvaluateKeyPoints(&context, request_of(1, false), &response).ok());
  ASSERT_EQ(response.results_size(), 1);
  expect_canned(response.results(0), 2 * kPoints * kChannels);
}

}  // namespace
}  // namespace animspace
