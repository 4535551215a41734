// PoseService.StreamKeyPoints and LodService.GetLod in process (tests/server/support): the two
// streams that share server/stream_reactor.h, seen through the generated stubs. Results leave in
// request order, a client that cancels mid-stream ends the call on the server (its metrics say
// so, and it keeps serving), and a stream cancelled while its work still waits on the pool
// finishes at once — the work then runs after gRPC is done with the call and is not done at all.
// Under check-asan these are also the streams' use-after-free checks.
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/lod.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "core/demo/demo_repository.h"
#include "server/services/key_point_stream.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::eventually;
using testing::Gate;
using testing::InProcessServer;
using testing::TempDir;

const std::string kPmsc(demo::kDemoPmscModelName);
const std::string kAnimationSpace(demo::kDemoAnimationSpaceModelName);

class StreamServicesTest : public testing::SmallRepositoryTest {
 protected:
  void serve(server::ServerOptions options = {}) {
    options.miss_log_dir = work_.path();
    server_ = std::make_unique<InProcessServer>(repository(), options);
    poses_ = v1::PoseService::NewStub(server_->channel());
    lod_ = v1::LodService::NewStub(server_->channel());
    v1::DescribeKeyPointsRequest request;
    request.mutable_model()->set_name(kPmsc);
    v1::DescribeKeyPointsResponse keys;
    grpc::ClientContext context;
    ASSERT_TRUE(poses_->DescribeKeyPoints(&context, request, &keys).ok());
    key_count_ = static_cast<uint32_t>(keys.key_point_indices_size());
    channels_ = keys.channel_count();
  }

  // A frame the soft cache can evaluate (any finite key values are a pose; hit or miss does not
  // matter here).
  v1::KeyPointFrame frame(uint64_t sequence) const {
    v1::KeyPointFrame f;
    if (sequence == kFirstSequence) f.mutable_model()->set_name(kPmsc);
    f.set_sequence(sequence);
    f.set_omit_points(true);
    v1::PointArray* values = f.mutable_pose()->mutable_key_values();
    values->set_point_count(key_count_);
    values->set_channel_count(channels_);
    const std::vector<float> data(size_t{key_count_} * channels_, 0.25f * static_cast<float>(sequence % 7));
    values->set_data(data.data(), data.size() * sizeof(float));
    return f;
  }

  int64_t calls_in_flight() const { return server_->environment().metrics.calls_in_flight(); }
  uint64_t poses_evaluated() const {
    const auto stats = server_->environment().metrics.model_statistics();
    const auto it = stats.find(kPmsc);
    return it == stats.end() ? 0 : it->second.poses;
  }

  static v1::GetLodRequest lod_request(uint32_t vertices_per_chunk) {
    v1::GetLodRequest r;
    r.mutable_model()->set_name(kAnimationSpace);
    r.set_level(0);
    r.set_form(v1::GetLodRequest::FORM_ANIMATION_SPACE);
    r.set_vertices_per_chunk(vertices_per_chunk);
    return r;
  }

  static constexpr uint64_t kFirstSequence = 100;
  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
  std::unique_ptr<v1::LodService::Stub> lod_;
  uint32_t key_count_ = 0;
  uint32_t channels_ = 0;
};

TEST_F(StreamServicesTest, KeyPointResultsLeaveInRequestOrderPastTheWindow) {
  serve();
  constexpr int kFrames = 3 * static_cast<int>(server::KeyPointStream::kWindow);
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  std::thread writer([&] {
    for (int i = 0; i < kFrames; ++i) {
      if (!stream->Write(frame(kFirstSequence + static_cast<uint64_t>(i)))) return;
    }
    stream->WritesDone();
  });
  v1::PoseResult result;
  uint64_t expected = kFirstSequence;
  while (stream->Read(&result)) {
    EXPECT_EQ(result.sequence(), expected);
    EXPECT_NE(result.status(), v1::CACHE_STATUS_UNSPECIFIED);
    ++expected;
  }
  writer.join();
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(expected, kFirstSequence + kFrames);
  EXPECT_EQ(poses_evaluated(), static_cast<uint64_t>(kFrames));
}

TEST_F(StreamServicesTest, AKeyPointStreamCancelledMidStreamEndsOnTheServer) {
  serve();
  {
    grpc::ClientContext context;
    auto stream = poses_->StreamKeyPoints(&context);
    std::thread writer([&] {
      for (uint64_t i = 0; i < 64; ++i) {
        if (!stream->Write(frame(kFirstSequence + i))) return;  // false once cancelled
      }
    });
    v1::PoseResult result;
    ASSERT_TRUE(stream->Read(&result));
    EXPECT_EQ(result.sequence(), kFirstSequence);
    context.TryCancel();
    writer.join();
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  EXPECT_TRUE(eventually([&] { return calls_in_flight() == 0; })) << calls_in_flight() << " calls still in flight";
  // The server carries on: a fresh stream is answered whole.
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  ASSERT_TRUE(stream->Write(frame(kFirstSequence)));
  stream->WritesDone();
  v1::PoseResult result;
  ASSERT_TRUE(stream->Read(&result));
  EXPECT_EQ(result.sequence(), kFirstSequence);
  EXPECT_FALSE(stream->Read(&result));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(StreamServicesTest, AKeyPointStreamCancelledWhileItsEvaluationWaitsOnThePoolFinishesAtOnce) {
  server::ServerOptions options;
  options.work_threads = 1;
  serve(options);
  server::WorkPool& pool = server_->environment().request_pool;
  // The pool's one thread is held, so the stream's evaluation can only wait behind it. The gates
  // are shared with the task, and `held` opens whichever way the test ends.
  auto held = std::make_shared<Gate>();
  auto running = std::make_shared<Gate>();
  struct OpenOnExit {
    std::shared_ptr<Gate> gate;
    ~OpenOnExit() { gate->open(); }
  } release{held};
  ASSERT_TRUE(pool.submit([held, running] {
    running->open();
    held->wait();
  }));
  running->wait();
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  ASSERT_TRUE(stream->Write(frame(kFirstSequence)));
  ASSERT_TRUE(eventually([&] { return pool.queued() == 1; }));
  context.TryCancel();
  EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  // The server finished the call without waiting for the evaluation it will never write.
  EXPECT_TRUE(eventually([&] { return calls_in_flight() == 0; }));
  held->open();
  // One thread, in order: once this runs, the stream's evaluation has run — after OnDone.
  auto drained = std::make_shared<Gate>();
  ASSERT_TRUE(pool.submit([drained] { drained->open(); }));
  drained->wait();
  EXPECT_EQ(poses_evaluated(), 0u) << "the work of a finished stream is skipped, not done";
}

TEST_F(StreamServicesTest, LodChunksArriveInOrderAndCoverTheLevel) {
  serve();
  grpc::ClientContext context;
  auto stream = lod_->GetLod(&context, lod_request(/*vertices_per_chunk=*/16));
  v1::LodChunk chunk;
  ASSERT_TRUE(stream->Read(&chunk));
  ASSERT_TRUE(chunk.has_header());
  const uint32_t vertices = chunk.header().vertex_count();
  ASSERT_GT(vertices, 32u) << "the level must span several blocks";
  uint32_t next_vertex = 0;
  bool skeleton = false;
  while (stream->Read(&chunk)) {
    if (chunk.has_vertices()) {
      EXPECT_EQ(chunk.vertices().first_vertex(), next_vertex);
      EXPECT_LE(chunk.vertices().vertex_count(), 16u);
      next_vertex += chunk.vertices().vertex_count();
    }
    skeleton = skeleton || chunk.has_skeleton();
  }
  EXPECT_TRUE(stream->Finish().ok());
  EXPECT_EQ(next_vertex, vertices);
  EXPECT_TRUE(skeleton);
}

TEST_F(StreamServicesTest, ALodStreamCancelledMidStreamEndsOnTheServer) {
  serve();
  {
    grpc::ClientContext context;
    auto stream = lod_->GetLod(&context, lod_request(/*vertices_per_chunk=*/1));
    v1::LodChunk chunk;
    ASSERT_TRUE(stream->Read(&chunk));
    EXPECT_TRUE(chunk.has_header());
    ASSERT_TRUE(stream->Read(&chunk));
    EXPECT_TRUE(chunk.has_vertices());
    context.TryCancel();
    while (stream->Read(&chunk)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  EXPECT_TRUE(eventually([&] { return calls_in_flight() == 0; })) << calls_in_flight() << " calls still in flight";
  grpc::ClientContext context;
  auto stream = lod_->GetLod(&context, lod_request(0));
  v1::LodChunk chunk;
  while (stream->Read(&chunk)) {
  }
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(StreamServicesTest, ABadLodRequestIsRefusedBeforeAnyChunk) {
  serve();
  auto request = lod_request(0);
  request.set_form(v1::GetLodRequest::FORM_UNSPECIFIED);
  grpc::ClientContext context;
  auto stream = lod_->GetLod(&context, request);
  v1::LodChunk chunk;
  EXPECT_FALSE(stream->Read(&chunk));
  const grpc::Status status = stream->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("form: expected FORM_ANIMATION_SPACE or FORM_POSED"), std::string::npos)
      << status.error_message();
}

TEST_F(StreamServicesTest, AKeyPointStreamWhoseFirstFrameNamesNoModelIsRefused) {
  serve();
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  v1::KeyPointFrame unnamed = frame(kFirstSequence);
  unnamed.clear_model();
  ASSERT_TRUE(stream->Write(unnamed));
  stream->WritesDone();
  v1::PoseResult result;
  EXPECT_FALSE(stream->Read(&result));
  const grpc::Status status = stream->Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("frame[sequence=100].model.name"), std::string::npos) << status.error_message();
}

}  // namespace
}  // namespace animspace
