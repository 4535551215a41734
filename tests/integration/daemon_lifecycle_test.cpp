// The real animspaced binary, started on an ephemeral port with a temporary repository and
// driven only through the gRPC protocol, as a client would.
#include <signal.h>

#include <thread>

#include <gtest/gtest.h>

#include "animspace/v1/render.grpc.pb.h"
#include "clients/cpp/client.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace animspace {
namespace {

using grpc::health::v1::HealthCheckResponse;
using harness::DaemonProcess;
using testing::TempDir;
using testing::write_model;

void wait_until_serving(Client& client) {
  ASSERT_TRUE(testing::wait_until_serving(client)) << "never SERVING";
}

// A tetrahedron with two frames: every count below is known by hand.
container::ModelContainer tetrahedron_model() {
  container::ModelContainer model;
  model.metadata()["kind"] = "mesh_sequence";
  model.metadata()["description"] = "hand-made tetrahedron";
  PointMatrix V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  FaceMatrix F(4, 3);
  F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  FrameMatrix frames(2, 12);
  frames.row(0) = Eigen::Map<const Eigen::RowVectorXf>(V.data(), 12);
  frames.row(1) = frames.row(0) * 2.0f;
  model.set_points("mesh.rest_points", V);
  model.set_faces("mesh.faces", F);
  model.set_matrix("sequence.frames", frames);
  return model;
}


class DaemonTest : public ::testing::Test {
 protected:
  void SetUp() override {
    repo_ = work_.path() / "repo";
    ASSERT_TRUE(testing::write_demo_repository(repo_).ok());
    write_model(repo_, "tetra", 3, tetrahedron_model());
    // A model whose only version is garbage: listed as refused, never served.
    std::filesystem::create_directories(repo_ / "broken" / "1");
    testing::write_text_file(repo_ / "broken" / "1" / "model.anim", "this is not a model container");
  }

  std::unique_ptr<DaemonProcess> start(std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--model-repository", repo_.string(), "--log-level", "debug"};
    args.insert(args.end(), extra.begin(), extra.end());
    return std::make_unique<DaemonProcess>(args, work_.path());
  }

  TempDir work_;
  std::filesystem::path repo_;
};

TEST_F(DaemonTest, ServesTheRepositoryAndStopsCleanlyOnSigterm) {
  auto daemon = start();
  Client client(daemon->address());
  wait_until_serving(client);

  const auto models = client.list_models();
  ASSERT_EQ(models.size(), 7u);
  EXPECT_EQ(models[0].name(), "arm");
  EXPECT_EQ(models[1].name(), "arm-animspace");
  EXPECT_EQ(models[2].name(), "arm-cross-pmsc");
  EXPECT_EQ(models[3].name(), "arm-pmsc");
  EXPECT_EQ(models[4].name(), "arm-pmsc-engine");
  EXPECT_EQ(models[5].name(), "broken");
  EXPECT_EQ(models[6].name(), "tetra");

  const auto& tetra = models[6];
  EXPECT_EQ(tetra.default_version(), 3u);
  ASSERT_EQ(tetra.versions_size(), 1);
  const auto& v = tetra.versions(0);
  EXPECT_EQ(v.state(), v1::VERSION_STATE_AVAILABLE);
  EXPECT_EQ(v.kind(), v1::MODEL_KIND_MESH_SEQUENCE);
  EXPECT_EQ(v.point_count(), 4u);
  EXPECT_EQ(v.channel_count(), 3u);
  EXPECT_EQ(v.face_count(), 4u);
  EXPECT_EQ(v.frame_count(), 2u);
  EXPECT_EQ(v.description(), "hand-made tetrahedron");
  EXPECT_EQ(v.file_size_bytes(), std::filesystem::file_size(repo_ / "tetra/3/model.anim"));

  // The refused model is visible with its reason, and has nothing to serve.
  const auto& broken = models[5];
  EXPECT_EQ(broken.default_version(), 0u);
  ASSERT_EQ(broken.versions_size(), 1);
  EXPECT_EQ(broken.versions(0).state(), v1::VERSION_STATE_FAILED);
  EXPECT_NE(broken.versions(0).error().find("model.anim"), std::string::npos) << broken.versions(0).error();

  // The demo arm matches its file, read independently of the server.
  auto arm_file = container::read_file(demo::demo_model_path(repo_));
  ASSERT_TRUE(arm_file.ok());
  const auto arm = client.describe_model("arm");
  ASSERT_EQ(arm.versions_size(), 1);
  EXPECT_EQ(arm.versions(0).point_count(), arm_file->points("mesh.rest_points")->rows());
  EXPECT_EQ(arm.versions(0).bone_count(), 2u);
  EXPECT_EQ(arm.versions(0).frame_count(), static_cast<uint32_t>(demo::kDemoFrames));

  // The animation-space demo: kind, root + 2 arm bones, and its points, read from the file.
  auto animspace_file = container::read_file(repo_ / "arm-animspace" / "1" / "model.anim");
  ASSERT_TRUE(animspace_file.ok());
  const auto animspace_model = client.describe_model("arm-animspace").versions(0);
  EXPECT_EQ(animspace_model.kind(), v1::MODEL_KIND_ANIMATION_SPACE);
  EXPECT_EQ(animspace_model.bone_count(), 3u);
  EXPECT_EQ(animspace_model.point_count(), animspace_file->points("mesh.rest_points")->rows());

  // The PMSC demo models describe their soft cache, read back from the files independently.
  for (const char* name : {"arm-pmsc", "arm-cross-pmsc"}) {
    auto file = container::read_file(repo_ / name / "1" / "model.anim");
    ASSERT_TRUE(file.ok()) << name;
    const auto described = client.describe_model(name).versions(0);
    const bool cross = std::string(name) == "arm-cross-pmsc";
    EXPECT_EQ(described.kind(), cross ? v1::MODEL_KIND_CROSS_PMSC : v1::MODEL_KIND_PMSC) << name;
    EXPECT_EQ(described.fail_through(), cross ? v1::FAIL_THROUGH_IMPOSSIBLE : v1::FAIL_THROUGH_CLIENT) << name;
    EXPECT_EQ(described.key_point_count(), file->int_matrix("pmsc.key_points")->rows()) << name;
    EXPECT_EQ(described.basis_size(), file->float_matrix("pmsc.basis")->cols()) << name;
    EXPECT_EQ(described.epsilon_min(), static_cast<float>((*file->double_matrix("pmsc.epsilon"))(0, 0))) << name;
    EXPECT_GT(described.epsilon_min(), 0.0f) << name;
    EXPECT_GE(described.epsilon_max(), described.epsilon_min()) << name;
  }

  daemon->send_signal(SIGTERM);
  EXPECT_EQ(daemon->wait_for_exit(std::chrono::seconds(15)), 0) << daemon->log();
  const std::string log = daemon->log();
  EXPECT_NE(log.find("health SERVING"), std::string::npos) << log;
  EXPECT_NE(log.find("received SIGTERM"), std::string::npos) << log;
  EXPECT_NE(log.find("stopped"), std::string::npos) << log;
}

TEST_F(DaemonTest, SigintAlsoStopsCleanly) {
  auto daemon = start();
  Client client(daemon->address());
  wait_until_serving(client);
  daemon->send_signal(SIGINT);
  EXPECT_EQ(daemon->wait_for_exit(std::chrono::seconds(15)), 0) << daemon->log();
}

TEST_F(DaemonTest, BadRequestsGetPreciseStatuses) {
  auto daemon = start();
  Client client(daemon->address());
  wait_until_serving(client);

  struct Case {
    std::string name;
    uint64_t version;
    grpc::StatusCode code;
    std::string message_part;
  };
  const std::vector<Case> cases = {
      {"nosuchmodel", 0, grpc::StatusCode::NOT_FOUND, "nosuchmodel"},
      {"../etc", 0, grpc::StatusCode::INVALID_ARGUMENT, "model.name"},
      {"", 0, grpc::StatusCode::INVALID_ARGUMENT, "model.name is empty"},
      {"a/b", 0, grpc::StatusCode::INVALID_ARGUMENT, "model.name"},
      {"tetra", 9, grpc::StatusCode::NOT_FOUND, "version 9"},
  };
  for (const auto& c : cases) {
    try {
      client.describe_model(c.name, c.version);
      ADD_FAILURE() << "describe '" << c.name << "' succeeded";
    } catch (const RpcError& e) {
      EXPECT_EQ(e.code(), c.code) << c.name << ": " << e.what();
      EXPECT_NE(e.server_message().find(c.message_part), std::string::npos) << e.server_message();
    }
  }
}

TEST_F(DaemonTest, LoadAndUnloadAtRunTime) {
  auto daemon = start();
  Client client(daemon->address());
  wait_until_serving(client);

  client.unload_model("tetra");
  try {
    client.describe_model("tetra");
    ADD_FAILURE() << "unloaded model still described";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::NOT_FOUND);
  }

  // A new version appears on disk; loading the model picks it up as the default.
  write_model(repo_, "tetra", 4, tetrahedron_model());
  const auto loaded = client.load_model("tetra");
  EXPECT_EQ(loaded.default_version(), 4u);
  EXPECT_EQ(loaded.versions_size(), 2);

  // Loading a corrupt version is refused and the serving version is kept.
  std::filesystem::create_directories(repo_ / "tetra" / "5");
  std::string bytes = container::serialize(tetrahedron_model());
  bytes.resize(bytes.size() / 2);  // truncated
  testing::write_text_file(repo_ / "tetra" / "5" / "model.anim", bytes);
  try {
    client.load_model("tetra", 5);
    ADD_FAILURE() << "truncated version loaded";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::FAILED_PRECONDITION) << e.what();
  }
  EXPECT_EQ(client.describe_model("tetra").default_version(), 4u);

  try {
    client.unload_model("nosuchmodel");
    ADD_FAILURE() << "unloading an unknown model succeeded";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::NOT_FOUND);
  }
}

TEST_F(DaemonTest, ReflectionListsTheApi) {
  auto daemon = start();
  Client client(daemon->address());
  wait_until_serving(client);

  auto stub = grpc::reflection::v1alpha::ServerReflection::NewStub(client.channel());
  grpc::ClientContext context;
  auto stream = stub->ServerReflectionInfo(&context);
  grpc::reflection::v1alpha::ServerReflectionRequest request;
  request.set_list_services("");
  ASSERT_TRUE(stream->Write(request));
  stream->WritesDone();
  grpc::reflection::v1alpha::ServerReflectionResponse response;
  ASSERT_TRUE(stream->Read(&response));
  std::set<std::string> services;
  for (const auto& s : response.list_services_response().service()) services.insert(s.name());
  for (const char* expected : {"animspace.v1.ModelService", "animspace.v1.PoseService", "animspace.v1.SkinningService",
                               "animspace.v1.LodService", "animspace.v1.RenderService",
                               "animspace.v1.TrainingService", "animspace.v1.StatsService", "grpc.health.v1.Health"}) {
    EXPECT_TRUE(services.count(expected)) << expected;
  }
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(DaemonTest, PrometheusMetricsCountCalls) {
  // A port free right now; the tiny race with other processes is acceptable in a test.
  const int metrics_port = testing::free_tcp_port();
  auto daemon = start({"--metrics-listen", "127.0.0.1:" + std::to_string(metrics_port)});
  Client client(daemon->address());
  wait_until_serving(client);
  client.describe_model("tetra");
  client.describe_model("tetra");
  EXPECT_THROW(client.describe_model("nosuchmodel"), RpcError);

  httplib::Client http("127.0.0.1", metrics_port);
  auto result = http.Get("/metrics");
  ASSERT_TRUE(result) << "no answer from the metrics endpoint";
  EXPECT_EQ(result->status, 200);
  const std::string& body = result->body;
  EXPECT_NE(body.find("animspace_models_loaded 6\n"), std::string::npos) << body;
  EXPECT_NE(body.find("animspace_requests_total{rpc=\"ModelService/DescribeModel\",model=\"tetra\",code=\"OK\"} 2\n"),
            std::string::npos)
      << body;
  // An unknown model is counted, but its name never becomes a label (clients could mint them).
  EXPECT_NE(body.find("rpc=\"ModelService/DescribeModel\",model=\"\",code=\"NOT_FOUND\"} 1\n"), std::string::npos)
      << body;
  EXPECT_EQ(body.find("nosuchmodel"), std::string::npos) << body;
  EXPECT_NE(body.find("animspace_model_version_serving{model=\"tetra\",version=\"3\",default=\"1\"} 1\n"),
            std::string::npos)
      << body;

  const auto stats = client.stats("tetra");
  ASSERT_EQ(stats.models_size(), 1);
  EXPECT_EQ(stats.models(0).requests(), 2u);
  EXPECT_EQ(stats.models(0).errors(), 0u);
  // Describing a model administers it: counted among its requests, not in its serving latency.
  EXPECT_EQ(stats.models(0).latency_seconds().total_count(), 0u);
}

TEST_F(DaemonTest, ServerInfoReportsLimitsFromFlags) {
  auto daemon = start({"--max-batch-poses", "77", "--max-message-bytes", "1048576", "--grpc-memory-bytes", "4194304"});
  Client client(daemon->address());
  wait_until_serving(client);
  const auto info = client.server_info();
  EXPECT_EQ(info.api(), "animspace.v1");
  EXPECT_EQ(info.max_batch_poses(), 77u);
  EXPECT_EQ(info.max_message_bytes(), 1048576u);
  EXPECT_EQ(info.grpc_memory_bytes(), 4194304u);
  bool lists_describe = false;
  for (const auto& rpc : info.implemented_rpcs()) lists_describe |= rpc == "animspace.v1.ModelService/DescribeModel";
  EXPECT_TRUE(lists_describe);
}

TEST(DaemonStartup, RefusesAMissingRepositoryWithAMessage) {
  TempDir work;
  try {
    DaemonProcess daemon({"--model-repository", (work.path() / "absent").string()}, work.path(),
                         std::chrono::seconds(10));
    // It may write its port before checking the repository; then it must exit non-zero.
    EXPECT_NE(daemon.wait_for_exit(std::chrono::seconds(10)), 0);
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("is not a directory"), std::string::npos) << e.what();
  }
}

TEST(DaemonStartup, RefusesAGrpcMemoryBoundTooSmallForTheLargestMessage) {
  TempDir work;
  // 1.5 MiB cannot hold a 1 MiB request while it arrives: the rule is twice --max-message-bytes.
  EXPECT_THROW(
      {
        try {
          DaemonProcess daemon({"--model-repository", work.path().string(), "--max-message-bytes", "1048576",
                                "--grpc-memory-bytes", "1572864"},
                               work.path(), std::chrono::seconds(10));
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("--grpc-memory-bytes: expected 0 (unbounded) or at least twice "
                                               "--max-message-bytes (2097152), got 1572864"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      std::runtime_error);
  // Exactly twice, and 0, are accepted. (An empty repository: no demo to generate, which is slow
  // under a sanitizer.)
  for (const char* bytes : {"2097152", "0"}) {
    DaemonProcess daemon({"--model-repository", work.path().string(), "--max-message-bytes", "1048576",
                          "--grpc-memory-bytes", bytes},
                         work.path());
    Client client(daemon.address());
    wait_until_serving(client);
  }
}

// Issue #21: gRPC's default SO_REUSEPORT let a second daemon bind a busy address and answer a
// random share of the calls. The second one must fail to start, naming the address and the first.
TEST(DaemonStartup, RefusesAnAddressAnotherDaemonListensOn) {
  TempDir first_dir;
  TempDir second_dir;
  DaemonProcess first({"--model-repository", first_dir.path().string(), "--metrics-listen", "127.0.0.1:0"},
                      first_dir.path());
  const std::string busy = first.address();
  const std::string first_pid = "pid " + std::to_string(first.pid());
  auto refusal = [&](const std::vector<std::string>& args) {
    try {
      DaemonProcess second(args, second_dir.path(), std::chrono::seconds(30));
      // It may write its port before a later step fails; then it must exit non-zero.
      EXPECT_NE(second.wait_for_exit(std::chrono::seconds(30)), 0);
      return second.log();
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
  };

  const std::string grpc_refusal = refusal({"--model-repository", second_dir.path().string(), "--listen", busy});
  EXPECT_NE(grpc_refusal.find("--listen: '" + busy + "' is already in use by " + first_pid), std::string::npos)
      << grpc_refusal;

  // The metrics endpoint is an address too (cpp-httplib also defaults to SO_REUSEPORT).
  std::string metrics_address;
  const std::string marker = "metrics on http://";
  ASSERT_TRUE(testing::wait_until([&] {
    const std::string log = first.log();
    const auto at = log.find(marker);
    if (at == std::string::npos) return false;
    const auto end = log.find("/metrics", at + marker.size());
    metrics_address = log.substr(at + marker.size(), end - at - marker.size());
    return end != std::string::npos;
  })) << first.log();
  const std::string metrics_refusal =
      refusal({"--model-repository", second_dir.path().string(), "--metrics-listen", metrics_address});
  EXPECT_NE(metrics_refusal.find("--metrics-listen: '" + metrics_address + "' is already in use by " + first_pid),
            std::string::npos)
      << metrics_refusal;

  // The first daemon still answers.
  Client client(busy);
  wait_until_serving(client);
}

TEST(DaemonStartup, ServesTheBundledDemoWithNoRepositoryFlag) {
  TempDir work;
  // The daemon writes the demo repository before it listens, the Cornell box's gathers and
  // training and arm-smooth's atlas and levels included: a few seconds here, 100–210 s measured
  // under ThreadSanitizer on two cores shared with builds. The bound is for a loaded machine.
  DaemonProcess daemon({}, work.path(), std::chrono::minutes(10));
  Client client(daemon.address());
  wait_until_serving(client);
  const auto models = client.list_models();
  // The five arm models, the articulated arm, the Cornell box's illumination and the subdivided
  // arm with its atlas.
  ASSERT_EQ(models.size(), 8u);
  for (const auto& model : models) {
    EXPECT_EQ(model.versions(0).state(), v1::VERSION_STATE_AVAILABLE) << model.name() << ": " << model.versions(0).error();
  }
  EXPECT_EQ(models[0].name(), "arm");
  EXPECT_EQ(models[2].name(), "arm-articulated");
  EXPECT_EQ(models[2].versions(0).subspace_kind(), v1::SUBSPACE_KIND_ARTICULATED);
  EXPECT_EQ(models[6].name(), "arm-smooth");
  EXPECT_EQ(models[6].versions(0).kind(), v1::MODEL_KIND_ANIMATION_SPACE);
  EXPECT_EQ(models[7].name(), "cornell");
  EXPECT_EQ(models[7].versions(0).server_engine(), v1::SERVER_ENGINE_ILLUMINATION);
  daemon.send_signal(SIGTERM);
  EXPECT_EQ(daemon.wait_for_exit(std::chrono::seconds(15)), 0) << daemon.log();
}

}  // namespace
}  // namespace animspace
