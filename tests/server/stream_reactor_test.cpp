// server/stream_reactor.h through a real gRPC server in the process: a generic bidi method whose
// reactor is the helper with a trivial domain (each message read is one unit of pool work that
// answers the message back), where the work waits on gates the test opens. Gates turn what are
// races in a real service into fixed orders: work finishing in reverse, a client cancelling while
// work is still running, work completing after gRPC has called OnDone. Under check-asan these
// tests are also the lifetime rule's use-after-free check.
#include "server/stream_reactor.h"

#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "server/metrics.h"
#include "server/work_pool.h"
#include "tests/server/support/in_process_server.h"

namespace animspace::server {
namespace {

using testing::eventually;
using testing::Gate;

constexpr const char* kMethod = "/animspace.test.Gated/Echo";

grpc::ByteBuffer bytes_of(const std::string& text) {
  grpc::Slice slice(text);
  return grpc::ByteBuffer(&slice, 1);
}

std::string text_of(const grpc::ByteBuffer& bytes) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(bytes.Dump(&slices).ok());
  std::string text;
  for (const auto& s : slices) text.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return text;
}

// What the reactors report to the test.
struct Probe {
  std::mutex mutex;
  std::map<int, Gate> gates;  // work i waits on gates[i]
  int started = 0;            // units of work running or done
  int completed = 0;          // units of work returned
  bool on_done = false;       // gRPC called OnDone
  bool deleted = false;       // the last hold was dropped
  bool completed_after_on_done = false;

  Gate& gate(int i) {
    std::lock_guard lock(mutex);
    return gates[i];
  }
  template <typename Read>
  auto read(Read what) {
    std::lock_guard lock(mutex);
    return what(*this);
  }
};

class GatedEcho final
    : public StreamReactor<grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>, grpc::ByteBuffer> {
 public:
  static constexpr size_t kWindow = 4;

  GatedEcho(grpc::CallbackServerContext* context, WorkPool& pool, Metrics& metrics, Probe& probe)
      : StreamReactor(context, pool, metrics, "Gated/Echo"), probe_(probe) {
    pump();
  }
  ~GatedEcho() override {
    std::lock_guard lock(probe_.mutex);
    probe_.deleted = true;
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      end(grpc::Status::OK);
      pump();
      return;
    }
    const int index = reads_++;
    const std::string text = text_of(incoming_);
    submit([this, index, text] {
      probe_.read([](Probe& p) { return ++p.started; });
      probe_.gate(index).wait();
      probe_.read([](Probe& p) {
        ++p.completed;
        p.completed_after_on_done = p.on_done;
        return 0;
      });
      return Outcome::write(bytes_of(text));
    });
    pump();
  }

  void OnDone() override {
    probe_.read([](Probe& p) { return p.on_done = true; });
    StreamReactor::OnDone();
  }

 private:
  bool want_more(size_t unwritten, size_t) const override { return unwritten < kWindow; }
  void request_more() override { StartRead(&incoming_); }

  Probe& probe_;
  grpc::ByteBuffer incoming_;
  int reads_ = 0;
};

class GatedService final : public grpc::CallbackGenericService {
 public:
  GatedService(WorkPool& pool, Metrics& metrics, Probe& probe) : pool_(pool), metrics_(metrics), probe_(probe) {}
  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* context) override {
    return new GatedEcho(context, pool_, metrics_, probe_);
  }

 private:
  WorkPool& pool_;
  Metrics& metrics_;
  Probe& probe_;
};

// A blocking client of the generic method: one operation at a time on a completion queue. With a
// deadline, an answer that never comes fails the test instead of hanging it.
class Client {
 public:
  explicit Client(const std::shared_ptr<grpc::Channel>& channel,
                  std::chrono::seconds deadline = std::chrono::seconds(0))
      : stub_(channel) {
    if (deadline.count() > 0) context_.set_deadline(std::chrono::system_clock::now() + deadline);
    call_ = stub_.PrepareCall(&context_, kMethod, &queue_);
    call_->StartCall(tag());
    EXPECT_TRUE(next());
  }
  ~Client() {
    queue_.Shutdown();
    void* ignored_tag = nullptr;
    bool ignored_ok = false;
    while (queue_.Next(&ignored_tag, &ignored_ok)) {
    }
  }
  bool write(const std::string& text) {
    call_->Write(bytes_of(text), tag());
    return next();
  }
  void writes_done() {
    call_->WritesDone(tag());
    next();
  }
  std::optional<std::string> read() {
    grpc::ByteBuffer bytes;
    call_->Read(&bytes, tag());
    if (!next()) return std::nullopt;
    return text_of(bytes);
  }
  grpc::Status finish() {
    grpc::Status status;
    call_->Finish(&status, tag());
    next();
    return status;
  }
  void cancel() { context_.TryCancel(); }

 private:
  void* tag() { return this; }
  bool next() {
    void* got = nullptr;
    bool ok = false;
    EXPECT_TRUE(queue_.Next(&got, &ok));
    return ok;
  }

  grpc::GenericStub stub_;
  grpc::ClientContext context_;
  grpc::CompletionQueue queue_;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call_;
};

class StreamReactorTest : public ::testing::Test {
 protected:
  // In process by default; over TCP (HTTP/2, as clients reach the daemon) with `tcp`: the
  // in-process transport has no write buffering or flow control to get wrong.
  void serve(int pool_threads, bool tcp = false) {
    pool_ = std::make_unique<WorkPool>(pool_threads, "test-pool");
    service_ = std::make_unique<GatedService>(*pool_, metrics_, probe_);
    grpc::ServerBuilder builder;
    int port = 0;
    if (tcp) builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    builder.RegisterCallbackGenericService(service_.get());
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    channel_ = tcp ? grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials())
                   : server_->InProcessChannel(grpc::ChannelArguments());
  }
  void TearDown() override {
    // Every gate opened, so that no work is left waiting when the pool joins.
    for (int i = 0; i < 64; ++i) probe_.gate(i).open();
    if (server_) server_->Shutdown();
    if (pool_) pool_->stop();
  }
  bool deleted() {
    return probe_.read([](Probe& p) { return p.deleted; });
  }

  Metrics metrics_;
  Probe probe_;
  std::unique_ptr<WorkPool> pool_;
  std::unique_ptr<GatedService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
};

TEST_F(StreamReactorTest, ResponsesLeaveInRequestOrderWhateverOrderTheWorkFinishesIn) {
  serve(/*pool_threads=*/4);
  Client client(channel_);
  for (const char* text : {"a", "b", "c", "d"}) ASSERT_TRUE(client.write(text));
  ASSERT_TRUE(eventually([&] { return probe_.read([](Probe& p) { return p.started == 4; }); }));
  // The last request's work finishes first, the first request's last.
  for (int i = 3; i >= 0; --i) {
    probe_.gate(i).open();
    ASSERT_TRUE(eventually([&] { return probe_.read([&](Probe& p) { return p.completed == 4 - i; }); }));
  }
  for (const char* text : {"a", "b", "c", "d"}) EXPECT_EQ(client.read(), std::optional<std::string>(text));
  client.writes_done();
  EXPECT_EQ(client.read(), std::nullopt);
  EXPECT_TRUE(client.finish().ok());
  EXPECT_TRUE(eventually([&] { return deleted(); }));
}

// A client that sends a few requests and then waits for their answers, sending nothing more,
// still gets every answer while the next one is already produced behind the one being written.
// (Writes that asked gRPC to hold them for the next — a buffer hint — completed only when other
// traffic flushed them, and the write that would have flushed waited for that completion: this
// stream hung. The first answer also carries the response headers: grpc/grpc#34231.)
TEST_F(StreamReactorTest, AnswersReadyBehindEachOtherAllArriveWhileTheClientSendsNothingMore) {
  serve(/*pool_threads=*/3, /*tcp=*/true);
  Client client(channel_, std::chrono::seconds(60));
  for (const char* text : {"a", "b", "c"}) ASSERT_TRUE(client.write(text));
  ASSERT_TRUE(eventually([&] { return probe_.read([](Probe& p) { return p.started == 3; }); }));
  // The second and third answers are ready before the first is written.
  probe_.gate(1).open();
  probe_.gate(2).open();
  ASSERT_TRUE(eventually([&] { return probe_.read([](Probe& p) { return p.completed == 2; }); }));
  probe_.gate(0).open();
  for (const char* text : {"a", "b", "c"}) ASSERT_EQ(client.read(), std::optional<std::string>(text));
  client.writes_done();
  EXPECT_EQ(client.read(), std::nullopt);
  EXPECT_TRUE(client.finish().ok());
}

TEST_F(StreamReactorTest, ACancelledStreamFinishesAtOnceAndItsWorkCompletesAfterOnDone) {
  serve(/*pool_threads=*/1);
  Client client(channel_);
  ASSERT_TRUE(client.write("a"));
  ASSERT_TRUE(eventually([&] { return probe_.read([](Probe& p) { return p.started == 1; }); }));
  client.cancel();
  EXPECT_EQ(client.finish().error_code(), grpc::StatusCode::CANCELLED);
  // The server finished the call and gRPC is done with it while the work still runs: the work's
  // hold is all that keeps the reactor.
  ASSERT_TRUE(eventually([&] { return probe_.read([](Probe& p) { return p.on_done; }); }));
  EXPECT_EQ(metrics_.calls_in_flight(), 0);
  EXPECT_FALSE(deleted());
  EXPECT_EQ(probe_.read([](Probe& p) { return p.completed; }), 0);
  probe_.gate(0).open();
  ASSERT_TRUE(eventually([&] { return deleted(); }));
  EXPECT_TRUE(probe_.read([](Probe& p) { return p.completed == 1 && p.completed_after_on_done; }));
}

TEST_F(StreamReactorTest, ACancelWhileResponsesAreBeingWrittenFinishesCancelledAndFreesTheStream) {
  serve(/*pool_threads=*/2);
  for (int i = 0; i < 64; ++i) probe_.gate(i).open();
  Client client(channel_);
  // A window of requests: the server has produced them all and is writing the second when the
  // client, having read one, cancels.
  for (size_t i = 0; i < GatedEcho::kWindow; ++i) ASSERT_TRUE(client.write(std::to_string(i)));
  EXPECT_EQ(client.read(), std::optional<std::string>("0"));
  client.cancel();
  EXPECT_EQ(client.finish().error_code(), grpc::StatusCode::CANCELLED);
  ASSERT_TRUE(eventually([&] { return deleted(); }));
  EXPECT_TRUE(probe_.read([](Probe& p) { return p.on_done; }));
  EXPECT_EQ(metrics_.calls_in_flight(), 0);
  // The server recorded the call as cancelled (its metrics line, one per finished call).
  EXPECT_NE(metrics_.prometheus_text().find("code=\"CANCELLED\""), std::string::npos) << metrics_.prometheus_text();
}

}  // namespace
}  // namespace animspace::server
