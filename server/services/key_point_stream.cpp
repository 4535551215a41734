#include "server/services/key_point_stream.h"

#include <string>

#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/raw_messages.h"
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
      resolved = find_model(env_.registry, frame.model(), frame_field(frame.sequence()) + ".model", model_);
      if (resolved.ok()) resolved = require_pmsc(*model_);
      model_ref_ = frame.model();
      if (index == 0 && model_) set_model(model_->name);
    }
  } else if (resolved.ok() && !model_) {
    resolved = {grpc::StatusCode::INVALID_ARGUMENT,
                frame_field(frame.sequence()) + ".model.name: the first frame must name the model"};
  }
  if (!resolved.ok()) {
    end(std::move(resolved));
  } else {
    submit([this, frame = std::move(frame), model = model_] { return evaluate(frame, *model); });
  }
  pump();
}

KeyPointStream::Outcome KeyPointStream::evaluate(const v1::KeyPointFrame& frame, const LoadedModel& model) {
  const std::string encoding_field = frame_field(frame.sequence()) + ".points_encoding";
  if (grpc::Status s = check_points_encoding(frame.points_encoding(), encoding_field); !s.ok()) {
    return Outcome::end(std::move(s));
  }
  PoseInput input;
  if (grpc::Status s = decode_pose(model, frame.pose(), frame_field(frame.sequence()) + ".pose", input); !s.ok()) {
    return Outcome::end(std::move(s));
  }
  PoseOptions options;
  options.omit_points = frame.omit_points();
  options.points_encoding = frame.points_encoding();
  options.local_fail_through = frame.local_fail_through();
  v1::PoseResult result;
  if (grpc::Status s = evaluate_pose(env_, model, input, options, &result); !s.ok()) return Outcome::end(std::move(s));
  result.set_sequence(frame.sequence());
  grpc::ByteBuffer bytes;
  if (grpc::Status s = serialize_message(result, bytes); !s.ok()) return Outcome::end(std::move(s));
  return Outcome::write(std::move(bytes));
}

}  // namespace animspace::server
