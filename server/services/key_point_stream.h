// PoseService.StreamKeyPoints: plays a sequence, one PoseResult per KeyPointFrame, in order.
//
// Pipelined: up to kWindow frames are read ahead and evaluated on the request pool while earlier
// results are still being written, so a client that streams a sequence keeps both the network
// and the cores busy. Each frame is decoded as it arrives and waits in the batcher
// (server/pose_batcher.h), so the frames read ahead are reconstructed as one product by the first
// pool thread that gets to them; results still leave in request order (server/stream_reactor.h owns the
// ordering, the lifetime and cancellation). The model version is resolved on the first frame
// (version 0 = the default then) and pinned for the whole stream, so a hot swap never changes the
// key points a running stream must send (a later frame may name another model or version
// explicitly). A bad frame ends the stream, after the results before it, with the status
// EvaluateKeyPoints would give, naming the frame's sequence number; bytes that are not a
// KeyPointFrame end it with INVALID_ARGUMENT naming the message's place in the stream.
#pragma once

#include <cstdint>
#include <memory>

#include <grpcpp/grpcpp.h>

#include "animspace/v1/poses.pb.h"
#include "server/model_registry.h"
#include "server/pose_evaluation.h"
#include "server/service_environment.h"
#include "server/stream_reactor.h"

namespace animspace::server {

class KeyPointStream final
    : public StreamReactor<grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>, grpc::ByteBuffer> {
 public:
  // Frames read ahead of the one being written.
  static constexpr size_t kWindow = 8;

  // Authenticates and admits the stream; the reactor deletes itself when the call is done.
  static KeyPointStream* start(ServiceEnvironment& env, grpc::CallbackServerContext* context);

  void OnReadDone(bool ok) override;

 private:
  KeyPointStream(ServiceEnvironment& env, grpc::CallbackServerContext* context);

  bool want_more(size_t unwritten, size_t /*producing*/) const override { return unwritten < kWindow; }
  void request_more() override { StartRead(&incoming_); }
  // A frame on its way: read, decoded (here or on the pool), waiting in the batcher, evaluated.
  struct Pose {
    std::shared_ptr<const LoadedModel> model;
    v1::KeyPointFrame frame;
    bool decoded = false;
    PoseJob job;
    v1::PoseResult result;
    v1::PoseResult* result_pointer = &result;
    // Last: destroyed first, taking the pose out of the batcher before the memory it writes goes
    // (a frame skipped because the stream stopped is never finished).
    PoseRun run;
  };
  // Decodes the frame's pose and starts it through the pipeline (on the batched path, it waits in
  // the batcher).
  grpc::Status decode(Pose& pose);
  // One frame through the soft cache, on the request pool.
  Outcome evaluate(Pose& pose);

  ServiceEnvironment& env_;
  // Read by one reaction at a time: a read starts only after the previous one is answered.
  grpc::ByteBuffer incoming_;
  std::shared_ptr<const LoadedModel> model_;
  v1::ModelRef model_ref_;
  uint64_t messages_read_ = 0;
};

}  // namespace animspace::server
