// Every RPC of the animspace.v1 proto, sent bytes that are not its request message through
// grpc::GenericStub to the in-process server (tests/server/support): each answers INVALID_ARGUMENT
// naming the message it expected (server/raw_messages.h), where gRPC's generated handlers
// answered UNIMPLEMENTED with no message. The table is the proto's own descriptors, so an RPC
// added to the proto is covered without editing this file.
#include <memory>
#include <string>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/lod.pb.h"
#include "animspace/v1/models.pb.h"
#include "animspace/v1/poses.pb.h"
#include "animspace/v1/render.pb.h"
#include "animspace/v1/skinning.pb.h"
#include "animspace/v1/stats.pb.h"
#include "animspace/v1/training.pb.h"
#include "server/implemented_rpcs.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::InProcessServer;
using testing::TempDir;

// Byte strings no protobuf message parses, whatever its fields (protobuf encoding spec):
const std::vector<std::pair<std::string, std::string>> kGarbage = {
    {"wire type 7, which does not exist", std::string("\x0f", 1)},
    {"a length-delimited field 1 that claims 5 bytes and has 1", std::string("\x0a\x05\x01", 3)},
    {"a tag varint that never ends", std::string(11, '\xff')},
    {"an end-group tag with no group", std::string("\x0c", 1)},
};

struct Rpc {
  std::string path;        // "/animspace.v1.ModelService/LoadModel"
  std::string input_type;  // "animspace.v1.LoadModelRequest"
  bool streaming = false;  // client or server streaming
};

// Every method of every animspace.v1 service, from the descriptors the generated code registers.
std::vector<Rpc> proto_rpcs() {
  // Touch one message per file so that each file's descriptors are built.
  for (const google::protobuf::Descriptor* d :
       {v1::ListModelsRequest::descriptor(), v1::KeyPointFrame::descriptor(), v1::GetLodRequest::descriptor(),
        v1::RenderThumbnailRequest::descriptor(), v1::EvaluateSkeletonPoseRequest::descriptor(),
        v1::GetStatsRequest::descriptor(), v1::RetrainRequest::descriptor()}) {
    EXPECT_NE(d, nullptr);
  }
  std::vector<Rpc> rpcs;
  for (const char* file : {"animspace/v1/models.proto", "animspace/v1/poses.proto", "animspace/v1/skinning.proto",
                           "animspace/v1/lod.proto", "animspace/v1/render.proto", "animspace/v1/training.proto",
                           "animspace/v1/stats.proto"}) {
    const auto* descriptor = google::protobuf::DescriptorPool::generated_pool()->FindFileByName(file);
    EXPECT_NE(descriptor, nullptr) << file;
    if (descriptor == nullptr) continue;
    for (int s = 0; s < descriptor->service_count(); ++s) {
      const auto* service = descriptor->service(s);
      for (int m = 0; m < service->method_count(); ++m) {
        const auto* method = service->method(m);
        rpcs.push_back({"/" + service->full_name() + "/" + method->name(), method->input_type()->full_name(),
                        method->client_streaming() || method->server_streaming()});
      }
    }
  }
  return rpcs;
}

grpc::ByteBuffer bytes_of(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

// Sends `bytes` as the one request message of `rpc` and returns the call's status.
grpc::Status call_with(grpc::GenericStub& stub, const Rpc& rpc, const std::string& bytes) {
  grpc::CompletionQueue queue;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  grpc::Status status;
  void* tag = nullptr;
  bool ok = false;
  if (!rpc.streaming) {
    grpc::ByteBuffer response;
    auto call = stub.PrepareUnaryCall(&context, rpc.path, bytes_of(bytes), &queue);
    call->StartCall();
    call->Finish(&response, &status, &queue);
    EXPECT_TRUE(queue.Next(&tag, &ok));
  } else {
    auto call = stub.PrepareCall(&context, rpc.path, &queue);
    call->StartCall(&queue);
    EXPECT_TRUE(queue.Next(&tag, &ok));
    call->Write(bytes_of(bytes), &queue);
    EXPECT_TRUE(queue.Next(&tag, &ok));
    call->WritesDone(&queue);
    EXPECT_TRUE(queue.Next(&tag, &ok));
    // Whatever the server says before its status (it should say nothing) is read and dropped.
    for (;;) {
      grpc::ByteBuffer message;
      call->Read(&message, &queue);
      EXPECT_TRUE(queue.Next(&tag, &ok));
      if (!ok) break;
      ADD_FAILURE() << rpc.path << " answered unparsable bytes with a message";
    }
    call->Finish(&status, &queue);
    EXPECT_TRUE(queue.Next(&tag, &ok));
  }
  queue.Shutdown();
  while (queue.Next(&tag, &ok)) {
  }
  return status;
}

class UnparsableRequestTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // An empty repository: a request must be refused before any model is looked for.
    server::ServerOptions options;
    options.miss_log_dir = work_.path();
    server_ = std::make_unique<InProcessServer>(repository_.path(), options);
  }
  TempDir repository_;
  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
};

TEST_F(UnparsableRequestTest, EveryRpcAnswersInvalidArgumentNamingItsRequestMessage) {
  const std::vector<Rpc> rpcs = proto_rpcs();
  ASSERT_GE(rpcs.size(), 14u);
  grpc::GenericStub stub(server_->channel());
  for (const Rpc& rpc : rpcs) {
    for (const auto& [why, bytes] : kGarbage) {
      SCOPED_TRACE(rpc.path + " with " + why);
      const grpc::Status status = call_with(stub, rpc, bytes);
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
      EXPECT_NE(status.error_message().find("could not be parsed as " + rpc.input_type), std::string::npos)
          << status.error_message();
    }
  }
  // The server is unharmed: a well-formed call still answers.
  v1::ListModelsRequest list;
  const grpc::Status status =
      call_with(stub, {"/animspace.v1.ModelService/ListModels", "", false}, list.SerializeAsString());
  EXPECT_TRUE(status.ok()) << status.error_message();
}

TEST_F(UnparsableRequestTest, EveryRpcOfTheProtoIsImplemented) {
  // GetServerInfo's list and the proto agree, so the table above covers what the server reports.
  for (const Rpc& rpc : proto_rpcs()) {
    const std::string name = rpc.path.substr(1);
    bool listed = false;
    for (const char* implemented : server::kImplementedRpcs) listed = listed || name == implemented;
    EXPECT_TRUE(listed) << name << " is in the proto but not in server/implemented_rpcs.h";
  }
}

}  // namespace
}  // namespace animspace
