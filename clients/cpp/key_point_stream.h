// animspace::KeyPointStream — a session over PoseService.StreamKeyPoints for playing a sequence.
//
// The server answers frames in the order they were sent (it pipelines evaluation but writes in
// request order); the session checks that, so a caller can pair results with frames without
// bookkeeping. Back-pressure: at most `window` frames may be written whose results have not been
// read, so neither side buffers an unbounded sequence when the consumer is slower than the server.
//
// Typical use, two threads (the writer blocks while the window is full):
//   auto stream = client.open_stream("crane");
//   std::thread writer([&] { for (i…) stream->write({values_i}, i); stream->writes_done(); });
//   while (auto result = stream->read()) consume(*result);
//   writer.join();
//   stream->finish();  // throws RpcError when the stream failed (e.g. a bad frame)
// One thread alternates instead: read() before write() whenever in_flight() == window().
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "clients/cpp/results.h"

namespace animspace {

struct StreamOptions {
  uint64_t version = 0;  // 0: the served default, resolved and pinned by the server on frame 1
  bool omit_points = false;
  bool local_fail_through = false;  // as EvaluateOptions::local_fail_through, for every frame
  v1::PointEncoding points_encoding = v1::POINT_ENCODING_UNSPECIFIED;  // as EvaluateOptions', every frame
  bool skip_miss_log = false;  // as EvaluateOptions::skip_miss_log, for every frame
  // Most frames written and not yet answered-and-read (≥ 1).
  uint32_t window = 16;
  // Deadline for the whole stream; 0 = none (a sequence plays as long as it plays).
  std::chrono::milliseconds deadline{0};
};

class KeyPointStream {
 public:
  KeyPointStream(const KeyPointStream&) = delete;
  KeyPointStream& operator=(const KeyPointStream&) = delete;
  // Cancels a stream that was not finished.
  ~KeyPointStream();

  // Sends one frame numbered `sequence` (echoed in its result). Blocks while window() results
  // are unread. False when the stream has ended or broken; finish() then says why.
  bool write(const KeyPointPose& pose, uint64_t sequence);
  // Half-closes: no more frames. Idempotent.
  void writes_done();
  // The next result, in write order; nullopt once the server has closed the stream. Throws
  // std::runtime_error if the server answers a frame out of order.
  std::optional<PoseResult> read();
  // Waits for the server's final status after the last read(); throws RpcError on failure.
  void finish();
  // Abandons the stream: the server stops, and a writer blocked on the window returns false.
  void cancel();

  size_t in_flight() const;
  uint32_t window() const { return options_.window; }

 private:
  friend class Client;
  KeyPointStream(v1::PoseService::Stub& stub, std::unique_ptr<grpc::ClientContext> context, std::string model,
                 StreamOptions options);

  std::unique_ptr<grpc::ClientContext> context_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::KeyPointFrame, v1::PoseResult>> stream_;
  const std::string model_;
  const StreamOptions options_;

  mutable std::mutex mutex_;
  std::condition_variable window_open_;
  std::deque<uint64_t> unanswered_;  // sequence numbers written, oldest first
  bool first_frame_ = true;
  bool ended_ = false;        // the read side has closed
  bool writes_done_ = false;
  bool finished_ = false;
};

}  // namespace animspace
