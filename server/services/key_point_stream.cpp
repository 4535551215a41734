#include "server/services/key_point_stream.h"

#include <string>

#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/raw_messages.h"
#include "server/status_mapping.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

constexpr const char* kRpc = "PoseService/StreamKeyPoints";

std::string frame_field(uint64_t sequence) { return "frame[sequence=" + std::to_string(sequence) + "]"; }

}  // namespace

KeyPointStream::KeyPointStream(ServiceEnvironment& env, grpc::CallbackServerContext* context)
    : StreamReactor(context, env.request_pool, env.metrics, kRpc), env_(env) {}

KeyPointStream* KeyPointStream::start(ServiceEnvironment& env, grpc::CallbackServerContext* context) {
  auto* stream = new KeyPointStream(env, context);
  if (stream->admit(env, Access::kUser)) stream->pump();  // starts the first read
  return stream;
}

void KeyPointStream::OnReadDone(bool ok) {
  if (!ok) {
    end(grpc::Status::OK);  // the client has sent its last frame
    pump();
    return;
  }
  const uint64_t index = messages_read_++;
  v1::KeyPointFrame frame;
  grpc::Status resolved = parse_message(incoming_, "stream message " + std::to_string(index), frame);
  incoming_.Clear();
  // Resolve (or re-resolve) the model here, in order: cheap, and it pins the version.
  if (resolved.ok() && frame.has_model() && !frame.model().name().empty()) {
    const bool same =
        model_ && frame.model().name() == model_ref_.name() && frame.model().version() == model_ref_.version();
    if (!same) {
      resolved = find_model(env_.registry, frame.model(), frame_field(frame.sequence()) + ".model", model_, nullptr,
                            deadline());
      if (resolved.ok()) resolved = require_pmsc(*model_);
      model_ref_ = frame.model();
      if (index == 0 && model_) set_model(model_->name);
    }
  } else if (resolved.ok() && !model_) {
    resolved = invalid_argument(frame_field(frame.sequence()) + ".model.name: the first frame must name the model");
  }
  if (!resolved.ok()) {
    end(std::move(resolved));
    pump();
    return;
  }
  auto pose = std::make_shared<Pose>();
  pose->model = model_;
  pose->frame = std::move(frame);
  pose->job.options.omit_points = pose->frame.omit_points();
  pose->job.options.local_fail_through = pose->frame.local_fail_through();
  pose->job.options.log_misses = !pose->frame.skip_miss_log();
  pose->job.options.points_encoding = pose->frame.points_encoding();
  // An answer as coordinates with no engine input is one projection (no f̂, no full calculation):
  // evaluated right here, as the frame arrives.
  if (evaluated_in_place(pose->job.options.points_encoding, pose->job.options.local_fail_through,
                         pose->frame.pose())) {
    run_here([this, pose] { return evaluate(*pose); });  // pumps; `this` may be gone after it
    return;
  }
  // Decoded here, in order, so that the frames read ahead wait in the batcher together and the
  // first pool thread to await reconstructs them as one product. A frame whose key values the
  // server gathers is decoded on the pool: the gather takes milliseconds.
  if (!gathers_keys(pose->frame.pose())) {
    if (grpc::Status s = decode(*pose); !s.ok()) {
      end(std::move(s));
      pump();
      return;
    }
  }
  submit([this, pose] { return evaluate(*pose); });
  pump();
}

grpc::Status KeyPointStream::decode(Pose& pose) {
  const LoadedModel& model = *pose.model;
  const std::string field = frame_field(pose.frame.sequence());
  if (grpc::Status s = check_points_encoding(pose.job.options.points_encoding, field + ".points_encoding"); !s.ok()) {
    return s;
  }
  if (grpc::Status s = decode_pose(model, pose.frame.pose(), field + ".pose", pose.job.input); !s.ok()) return s;
  pose.decoded = true;
  pose.run.start(env_, model, {&pose.job, 1}, {&pose.result_pointer, 1});
  return grpc::Status::OK;
}

KeyPointStream::Outcome KeyPointStream::evaluate(Pose& pose) {
  if (!pose.decoded) {
    if (grpc::Status s = decode(pose); !s.ok()) return Outcome::end(std::move(s));
  }
  if (grpc::Status s = pose.run.finish(); !s.ok()) return Outcome::end(std::move(s));
  pose.result.set_sequence(pose.frame.sequence());
  grpc::ByteBuffer bytes;
  if (grpc::Status s = serialize_message(pose.result, bytes); !s.ok()) return Outcome::end(std::move(s));
  return Outcome::write(std::move(bytes));
}

}  // namespace animspace::server
