#include "clients/cpp/key_point_stream.h"

#include <stdexcept>

#include "clients/cpp/client.h"

namespace animspace {

KeyPointStream::KeyPointStream(v1::PoseService::Stub& stub, std::unique_ptr<grpc::ClientContext> context,
                               std::string model, StreamOptions options)
    : context_(std::move(context)), model_(std::move(model)), options_(options) {
  if (options_.window == 0) throw std::invalid_argument("StreamOptions.window must be at least 1, got 0");
  if (options_.deadline.count() > 0) context_->set_deadline(std::chrono::system_clock::now() + options_.deadline);
  stream_ = stub.StreamKeyPoints(context_.get());
}

KeyPointStream::~KeyPointStream() {
  if (finished_) return;
  // Abandoned mid-sequence: cancel so that the server stops evaluating, then collect the status
  // (Finish() after TryCancel returns promptly with CANCELLED).
  context_->TryCancel();
  v1::PoseResult ignored;
  while (stream_->Read(&ignored)) {
  }
  (void)stream_->Finish();
}

bool KeyPointStream::write(const KeyPointPose& pose, uint64_t sequence) {
  v1::KeyPointFrame frame;
  *frame.mutable_pose() = encode_key_point_pose(pose);
  frame.set_sequence(sequence);
  frame.set_omit_points(options_.omit_points);
  frame.set_local_fail_through(options_.local_fail_through);
  frame.set_skip_miss_log(options_.skip_miss_log);
  frame.set_points_encoding(options_.points_encoding);
  {
    std::unique_lock lock(mutex_);
    window_open_.wait(lock, [&] { return ended_ || unanswered_.size() < options_.window; });
    if (ended_ || writes_done_) return false;
    if (first_frame_) {
      frame.mutable_model()->set_name(model_);
      frame.mutable_model()->set_version(options_.version);
      first_frame_ = false;
    }
    // Recorded before the write: the answer may arrive before Write() returns.
    unanswered_.push_back(sequence);
  }
  return stream_->Write(frame);
}

void KeyPointStream::writes_done() {
  {
    std::lock_guard lock(mutex_);
    if (writes_done_) return;
    writes_done_ = true;
  }
  stream_->WritesDone();
}

std::optional<PoseResult> KeyPointStream::read() {
  v1::PoseResult wire;
  if (!stream_->Read(&wire)) {
    std::lock_guard lock(mutex_);
    ended_ = true;
    window_open_.notify_all();
    return std::nullopt;
  }
  uint64_t expected = 0;
  {
    std::lock_guard lock(mutex_);
    if (unanswered_.empty()) {
      throw std::runtime_error("StreamKeyPoints answered frame " + std::to_string(wire.sequence()) +
                               ", which was never sent (or was answered already)");
    }
    expected = unanswered_.front();
    unanswered_.pop_front();
    window_open_.notify_all();
  }
  if (wire.sequence() != expected) {
    throw std::runtime_error("StreamKeyPoints answered frame " + std::to_string(wire.sequence()) +
                             " out of order: expected frame " + std::to_string(expected));
  }
  return decode_pose_result(wire);
}

void KeyPointStream::finish() {
  if (finished_) return;
  {
    std::lock_guard lock(mutex_);
    // gRPC's Finish() waits for every answer to be read; one left unread would hang it.
    if (!ended_) throw std::logic_error("KeyPointStream::finish() before read() returned the end of the stream");
  }
  writes_done();
  finished_ = true;
  const grpc::Status status = stream_->Finish();
  if (!status.ok()) throw RpcError("StreamKeyPoints", status);
}

void KeyPointStream::cancel() {
  context_->TryCancel();
  std::lock_guard lock(mutex_);
  ended_ = true;
  window_open_.notify_all();
}

size_t KeyPointStream::in_flight() const {
  std::lock_guard lock(mutex_);
  return unanswered_.size();
}

}  // namespace animspace
