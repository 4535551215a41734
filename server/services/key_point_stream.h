// PoseService.StreamKeyPoints: plays a sequence, one PoseResult per KeyPointFrame, in order.
//
// Pipelined: up to kWindow frames are read ahead and evaluated on the request pool while earlier
// results are still being written, so a client that streams a sequence keeps both the network
// and the cores busy; results still leave in request order. The model version is resolved on the
// first frame (version 0 = the default then) and pinned for the whole stream, so a hot swap never
// changes the key points a running stream must send (a later frame may name another model or
// version explicitly). A bad frame ends the stream, after the results before it, with the status
// EvaluateKeyPoints would give, naming the frame's sequence number.
#pragma once

#include <deque>
#include <memory>
#include <mutex>

#include <grpcpp/grpcpp.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "server/admission.h"
#include "server/call_scope.h"
#include "server/model_registry.h"
#include "server/service_environment.h"

namespace animspace::server {

class KeyPointStream final : public grpc::ServerBidiReactor<v1::KeyPointFrame, v1::PoseResult> {
 public:
  // Frames read ahead of the one being written.
  static constexpr size_t kWindow = 8;

  // Authenticates and admits the stream; the reactor deletes itself when the call is done.
  static KeyPointStream* start(ServiceEnvironment& env, grpc::CallbackServerContext* context);

  void OnReadDone(bool ok) override;
  void OnWriteDone(bool ok) override;
  void OnCancel() override;
  void OnDone() override;

 private:
  struct Slot {
    v1::PoseResult result;
    bool ready = false;
    grpc::Status error;  // not OK: the stream ends here
  };

  KeyPointStream(ServiceEnvironment& env, grpc::CallbackServerContext* context);
  // Evaluates one frame on the request pool.
  void evaluate(Slot* slot, v1::KeyPointFrame frame, std::shared_ptr<const LoadedModel> model);
  // Starts what can start next (start_next), counted in pumping_ so that OnDone, which may run
  // as soon as Finish is called, leaves the deletion to the last pump still running.
  // `finished_evaluations`: evaluations that end here (see evaluate).
  void pump(int finished_evaluations = 0);
  // Decides, under the lock, what to start next (write, read, finish) and starts it outside it.
  void start_next(int finished_evaluations);

  ServiceEnvironment& env_;
  grpc::CallbackServerContext* context_;
  CallScope scope_;
  std::shared_ptr<Admission::Ticket> ticket_;

  std::mutex mutex_;
  v1::KeyPointFrame incoming_;
  std::deque<std::unique_ptr<Slot>> slots_;  // front: the next result to write
  std::shared_ptr<const LoadedModel> model_;
  v1::ModelRef model_ref_;
  uint64_t frames_read_ = 0;
  int evaluating_ = 0;
  bool reading_ = false;
  bool reads_done_ = false;
  bool writing_ = false;
  bool stopping_ = false;  // an error is queued or the call was cancelled: read no more
  bool cancelled_ = false;
  bool finished_ = false;
  int pumping_ = 0;    // pump() calls in progress
  bool done_ = false;  // OnDone has run: the last pump out deletes the reactor
};

}  // namespace animspace::server
