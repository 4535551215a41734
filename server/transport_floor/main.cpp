// animspace-transport-floor: PoseService with no work behind it, the floor under what animspaced
// can serve on a given machine (issue #25). EvaluateKeyPoints and StreamKeyPoints answer every
// pose with a canned PoseResult the size of the daemon's answer for an N-point, D-channel model
// (status HIT, N·D values of --bytes-per-value bytes each, an e_key and a model version), serialised
// once at start. Per call it only parses the request, as the daemon does, and copies the canned
// bytes; answers are computed inline on gRPC's callback thread, with no hop to a work pool.
//
// The gRPC server is built by the daemon's own make_server_builder (server/server_builder.h) from
// the same transport flags (server/transport_flags.h), so the two differ in the work per call
// only. Like animspaced it writes its bound port to --port-file and stops on SIGTERM/SIGINT, so
// harness::DaemonProcess starts it the same way.
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>

#include <CLI/CLI.hpp>
#include <grpc/slice.h>
#include <grpcpp/grpcpp.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "core/common/atomic_file.h"
#include "server/auth.h"
#include "server/listener.h"
#include "server/raw_messages.h"
#include "server/server_builder.h"
#include "server/transport_flags.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

// Bytes in one gRPC slice, copied once: the only per-answer copy besides gRPC's own.
grpc::ByteBuffer copy_to_buffer(std::initializer_list<std::string_view> parts) {
  size_t size = 0;
  for (std::string_view part : parts) size += part.size();
  grpc_slice raw = grpc_slice_malloc(size);
  uint8_t* out = GRPC_SLICE_START_PTR(raw);
  for (std::string_view part : parts) {
    std::memcpy(out, part.data(), part.size());
    out += part.size();
  }
  grpc::Slice slice(raw, grpc::Slice::STEAL_REF);
  return grpc::ByteBuffer(&slice, 1);
}

// What every answer is made of, serialised once.
class CannedResults {
 public:
  CannedResults(int point_count, int channel_count, int bytes_per_value, int64_t max_message_bytes)
      : max_message_bytes_(max_message_bytes) {
    v1::PoseResult result;
    result.set_status(v1::CACHE_STATUS_HIT);
    // A hit's e_key is non-zero, so the daemon's answer carries the field: so does this one.
    result.set_key_point_error(1e-3f);
    result.set_model_version(1);
    result.mutable_points()->set_point_count(static_cast<uint32_t>(point_count));
    result.mutable_points()->set_channel_count(static_cast<uint32_t>(channel_count));
    result_without_points_ = result.SerializeAsString();
    result.mutable_points()->mutable_data()->assign(
        static_cast<size_t>(point_count) * static_cast<size_t>(channel_count) * static_cast<size_t>(bytes_per_value),
        '\0');
    result_ = result.SerializeAsString();
    // A repeated message field's encoding is one tag-and-length entry per element, so a
    // response with n results is n copies of the one-result encoding.
    v1::EvaluateKeyPointsResponse response;
    response.add_results()->Swap(&result);
    response_entry_ = response.SerializeAsString();
    response.mutable_results(0)->clear_points();
    response.mutable_results(0)->mutable_points()->set_point_count(static_cast<uint32_t>(point_count));
    response.mutable_results(0)->mutable_points()->set_channel_count(static_cast<uint32_t>(channel_count));
    response_entry_without_points_ = response.SerializeAsString();
  }

  // The EvaluateKeyPoints answer to `request`, with the daemon's checks on the batch's size.
  grpc::Status unary(const v1::EvaluateKeyPointsRequest& request, uint32_t max_batch_poses,
                     grpc::ByteBuffer& out) const {
    const std::string& entry = request.omit_points() ? response_entry_without_points_ : response_entry_;
    if (grpc::Status s = check_batch_size(request.poses_size(), max_batch_poses, "poses"); !s.ok()) return s;
    if (grpc::Status s = check_response_size(request.poses_size(), entry.size(), max_message_bytes_, "poses");
        !s.ok()) {
      return s;
    }
    if (request.poses_size() == 1) {
      out = copy_to_buffer({entry});
    } else {
      std::string all;
      all.reserve(entry.size() * static_cast<size_t>(request.poses_size()));
      for (int i = 0; i < request.poses_size(); ++i) all += entry;
      out = copy_to_buffer({all});
    }
    return grpc::Status::OK;
  }

  // The StreamKeyPoints answer to `frame`: the canned result and the frame's sequence number.
  // Concatenated encodings of one message parse as their merge, so the sequence is appended.
  grpc::ByteBuffer frame_result(const v1::KeyPointFrame& frame) const {
    v1::PoseResult sequence;
    sequence.set_sequence(frame.sequence());
    return copy_to_buffer({frame.omit_points() ? result_without_points_ : result_, sequence.SerializeAsString()});
  }

  size_t result_bytes() const { return result_.size(); }

 private:
  int64_t max_message_bytes_;
  std::string result_, result_without_points_;                  // one PoseResult
  std::string response_entry_, response_entry_without_points_;  // a response with one result
};

// Read one frame, write its answer, read the next: answers leave in order, one write in flight,
// and a frame is read only after the previous answer went to the transport, so no reaction ever
// overlaps another and Finish is called exactly once, with nothing else outstanding.
class FloorStream final : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  explicit FloorStream(const CannedResults& canned) : canned_(canned) { StartRead(&incoming_); }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed (or went away): every frame has been answered
      Finish(grpc::Status::OK);
      return;
    }
    v1::KeyPointFrame frame;
    if (grpc::Status s = parse_message(incoming_, "stream message " + std::to_string(messages_read_), frame);
        !s.ok()) {
      Finish(s);
      return;
    }
    ++messages_read_;
    outgoing_ = canned_.frame_result(frame);
    StartWrite(&outgoing_);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the client went away"));
      return;
    }
    StartRead(&incoming_);
  }

  void OnDone() override { delete this; }

 private:
  const CannedResults& canned_;
  grpc::ByteBuffer incoming_, outgoing_;
  uint64_t messages_read_ = 0;
};

// The daemon's PoseService registration (every method raw, server/services/pose_service.h); the
// two methods not overridden answer UNIMPLEMENTED.
using RawPoseService = v1::PoseService::WithRawCallbackMethod_DescribeKeyPoints<
    v1::PoseService::WithRawCallbackMethod_EvaluateKeyPoints<v1::PoseService::WithRawCallbackMethod_StreamKeyPoints<
        v1::PoseService::WithRawCallbackMethod_CompleteMiss<v1::PoseService::Service>>>>;

class FloorPoseService final : public RawPoseService {
 public:
  FloorPoseService(const CannedResults& canned, uint32_t max_batch_poses)
      : canned_(canned), max_batch_poses_(max_batch_poses) {}

  grpc::ServerUnaryReactor* EvaluateKeyPoints(grpc::CallbackServerContext* context,
                                              const grpc::ByteBuffer* request_bytes,
                                              grpc::ByteBuffer* response_bytes) override {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    v1::EvaluateKeyPointsRequest request;
    grpc::Status status = parse_message(*request_bytes, "the request", request);
    if (status.ok()) status = canned_.unary(request, max_batch_poses_, *response_bytes);
    reactor->Finish(status);
    return reactor;
  }

  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* StreamKeyPoints(
      grpc::CallbackServerContext* /*context*/) override {
    return new FloorStream(canned_);
  }

 private:
  const CannedResults& canned_;
  uint32_t max_batch_poses_;
};

int run(int argc, char** argv) {
  ServerOptions options;
  int point_count = 0, channel_count = 3, bytes_per_value = 4;
  CLI::App app{"animspace-transport-floor — PoseService answering canned results of an N-point model: the "
               "transport floor under animspaced (animspace-bench serve)"};
  add_transport_flags(app, options);
  app.add_option("--point-count", point_count, "N: points per answer")->required()->check(CLI::Range(1, 1 << 28));
  app.add_option("--channel-count", channel_count, "D: channels per point")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--bytes-per-value", bytes_per_value,
                 "Bytes of each point value: 4 (float32) or 2 (a 16-bit points encoding)")
      ->check(CLI::IsMember({4, 2}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  // Stop signals are taken synchronously below; gRPC's threads inherit the mask.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  auto fail = [](const std::string& message) {
    std::fprintf(stderr, "animspace-transport-floor: %s\n", message.c_str());
    return EXIT_FAILURE;
  };
  if (Status s = check_transport_options(options); !s.ok()) return fail(s.error().message);
  auto credentials = make_server_credentials(options);
  if (!credentials) return fail(credentials.error().message);
  const CannedResults canned(point_count, channel_count, bytes_per_value, options.max_message_bytes);
  FloorPoseService service(canned, options.max_batch_poses);
  auto listener = Listener::bind(options.listen_address);
  if (!listener) return fail(listener.error().message);
  const int port = (*listener)->port();
  std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor;
  const auto builder = make_server_builder(options, *credentials, &acceptor);
  builder->RegisterService(&service);
  const std::unique_ptr<grpc::Server> server = builder->BuildAndStart();
  if (!server) return fail(start_failure(options).error().message);
  (*listener)->start(std::move(acceptor));
  std::fprintf(stderr, "animspace-transport-floor: listening on %s (port %d); %zu bytes per PoseResult\n",
               options.listen_address.c_str(), port, canned.result_bytes());
  if (!options.port_file.empty()) {
    if (Status s = write_file_atomically(options.port_file, std::to_string(port) + "\n"); !s.ok()) {
      return fail(s.error().message);
    }
  }
  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  (*listener)->stop();
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
  server->Wait();
  return EXIT_SUCCESS;
}

}  // namespace
}  // namespace animspace::server

int main(int argc, char** argv) { return animspace::server::run(argc, argv); }
