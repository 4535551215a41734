#include "server/services/key_point_stream.h"

#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/unary_call.h"

namespace animspace::server {
namespace {

constexpr const char* kRpc = "PoseService/StreamKeyPoints";

std::string frame_field(uint64_t sequence) { return "frame[sequence=" + std::to_string(sequence) + "]"; }

}  // namespace

KeyPointStream::KeyPointStream(ServiceEnvironment& env, grpc::CallbackServerContext* context)
    : env_(env), context_(context), scope_(env.metrics, kRpc) {}

KeyPointStream* KeyPointStream::start(ServiceEnvironment& env, grpc::CallbackServerContext* context) {
  auto* stream = new KeyPointStream(env, context);
  if (grpc::Status refused = admit(env, context, kRpc, Access::kUser, &stream->ticket_); !refused.ok()) {
    stream->finished_ = true;
    stream->Finish(stream->scope_.finish(refused));
    return stream;
  }
  stream->reading_ = true;
  stream->StartRead(&stream->incoming_);
  return stream;
}

void KeyPointStream::OnReadDone(bool ok) {
  {
    std::lock_guard lock(mutex_);
    reading_ = false;
    if (!ok) {
      reads_done_ = true;
    } else if (!stopping_ && !finished_) {
      v1::KeyPointFrame frame = std::move(incoming_);
      incoming_.Clear();
      const uint64_t index = frames_read_++;
      auto slot = std::make_unique<Slot>();
      Slot* target = slot.get();
      slots_.push_back(std::move(slot));
      // Resolve (or re-resolve) the model here, in order: cheap, and it pins the version.
      grpc::Status resolved = grpc::Status::OK;
      if (frame.has_model() && !frame.model().name().empty()) {
        const bool same = model_ && frame.model().name() == model_ref_.name() &&
                          frame.model().version() == model_ref_.version();
        if (!same) {
          resolved = find_model(env_.registry, frame.model(), frame_field(frame.sequence()) + ".model", model_);
          if (resolved.ok()) resolved = require_pmsc(*model_);
          model_ref_ = frame.model();
          if (index == 0 && model_) scope_.set_model(model_->name);
        }
      } else if (!model_) {
        resolved = {grpc::StatusCode::INVALID_ARGUMENT,
                    frame_field(frame.sequence()) + ".model.name: the first frame must name the model"};
      }
      if (!resolved.ok()) {
        target->error = resolved;
        target->ready = true;
        stopping_ = true;
      } else {
        ++evaluating_;
        const bool queued = env_.request_pool.submit(
            [this, target, frame = std::make_shared<v1::KeyPointFrame>(std::move(frame)), model = model_] {
              evaluate(target, std::move(*frame), model);
            });
        if (!queued) {
          --evaluating_;
          target->error = {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
          target->ready = true;
          stopping_ = true;
        }
      }
    }
  }
  pump();
}

void KeyPointStream::evaluate(Slot* slot, v1::KeyPointFrame frame, std::shared_ptr<const LoadedModel> model) {
  grpc::Status status = CallControl(context_, nullptr).stop_status();
  if (status.ok()) {
    PoseInput input;
    status = decode_pose(*model, frame.pose(), frame_field(frame.sequence()) + ".pose", input);
    if (status.ok()) {
      PoseOptions options;
      options.omit_points = frame.omit_points();
      evaluate_pose(env_, *model, input, options, &slot->result);
      slot->result.set_sequence(frame.sequence());
    }
  }
  {
    std::lock_guard lock(mutex_);
    slot->ready = true;
    if (!status.ok()) {
      slot->error = status;
      stopping_ = true;
    }
  }
  // The evaluation stops counting inside pump's critical section: counted until then, it keeps
  // the stream from finishing (and OnDone from deleting it) while this thread still uses it.
  pump(/*finished_evaluations=*/1);
}

void KeyPointStream::OnWriteDone(bool ok) {
  {
    std::lock_guard lock(mutex_);
    writing_ = false;
    slots_.pop_front();
    if (!ok) {
      // The client is gone (or cancelled): nothing more can be delivered.
      stopping_ = true;
      cancelled_ = true;
    }
  }
  pump();
}

void KeyPointStream::OnCancel() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    cancelled_ = true;
  }
  pump();
}

// gRPC calls OnDone after the last reaction, but a pool thread may still be inside pump(): it
// started a write or read, or called Finish, and has not returned yet. The last one out deletes.
void KeyPointStream::OnDone() {
  {
    std::lock_guard lock(mutex_);
    done_ = true;
    if (pumping_ > 0) return;
  }
  delete this;
}

void KeyPointStream::pump(int finished_evaluations) {
  {
    std::lock_guard lock(mutex_);
    ++pumping_;
  }
  start_next(finished_evaluations);
  bool last_out = false;
  {
    std::lock_guard lock(mutex_);
    last_out = --pumping_ == 0 && done_;
  }
  if (last_out) delete this;
}

void KeyPointStream::start_next(int finished_evaluations) {
  const v1::PoseResult* write = nullptr;
  bool read = false;
  bool finish = false;
  grpc::Status final_status;
  {
    std::lock_guard lock(mutex_);
    evaluating_ -= finished_evaluations;
    if (finished_) return;
    // Finishing waits for every evaluation on the pool: they point into this reactor.
    if (cancelled_) {
      if (!writing_ && evaluating_ == 0) {
        finish = true;
        final_status = {grpc::StatusCode::CANCELLED, "the client cancelled the stream"};
      }
    } else if (!writing_ && !slots_.empty() && slots_.front()->ready) {
      Slot& front = *slots_.front();
      if (!front.error.ok()) {
        if (evaluating_ == 0) {
          finish = true;
          final_status = front.error;
        }
      } else {
        writing_ = true;
        write = &front.result;
      }
    } else if (!writing_ && slots_.empty() && evaluating_ == 0 && reads_done_) {
      finish = true;
      final_status = grpc::Status::OK;
    }
    if (!finish && !reading_ && !reads_done_ && !stopping_ && slots_.size() < kWindow) {
      reading_ = true;
      read = true;
    }
    if (finish) finished_ = true;
  }
  if (finish) {
    ticket_->release();
    Finish(scope_.finish(std::move(final_status)));
    return;
  }
  if (write != nullptr) StartWrite(write);
  if (read) StartRead(&incoming_);
}

}  // namespace animspace::server
