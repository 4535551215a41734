// `animspace retrain-offline` as the nightly job of a scaled-out deployment: two replicas serve
// one repository, each logging its own misses under one root; the job folds every completed miss
// of both into the next version, publishes it atomically, and both replicas pick it up by
// polling. A second run finds nothing new (per-log watermarks); a new miss on one replica is
// folded in exactly once more.
#include <sys/wait.h>

#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"
#include "clients/cpp/coordinates.h"
#include "clients/cpp/key_point_stream.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/container/sections.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/retrain.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/metrics_scrape.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;

const std::string kModel(demo::kDemoPmscModelName);

// The client side of several replicas (docs/DEPLOY.md): a call that fails UNAVAILABLE — its
// replica gone — is tried again, on another replica, up to twice.
constexpr const char* kRoundRobinRetries = R"({"methodConfig": [{
  "name": [{"service": "animspace.v1.PoseService"}, {"service": "animspace.v1.ModelService"}],
  "retryPolicy": {"maxAttempts": 3, "initialBackoff": "0.01s", "maxBackoff": "0.2s", "backoffMultiplier": 2,
                  "retryableStatusCodes": ["UNAVAILABLE"]}}]})";

struct Replica {
  std::unique_ptr<DaemonProcess> daemon;
  std::unique_ptr<Client> client;
};

nlohmann::json retrain_offline(const std::filesystem::path& repo, const std::filesystem::path& logs,
                               const std::filesystem::path& scratch, const std::string& flags = "") {
  const auto out = scratch / "retrain.json";
  const std::string command = harness::program_path("animspace").string() + " --json retrain-offline --repository " +
                              repo.string() + " --model " + kModel + " --miss-logs " + logs.string() + flags + " > " +
                              out.string() + " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream in(out);
  std::string text((std::istreambuf_iterator<char>(in)), {});
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << text;
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception&) {
    ADD_FAILURE() << "not JSON: " << text;
    return {};
  }
}

// A completed miss, acknowledged: frame `frame` of the arm with its points pushed `push` along
// `axis` (so that a later miss can be unlike what an earlier one taught), evaluated on the version
// `client` serves now with that version's key points (a retrain may choose others), its full
// values sent back and logged.
void complete_one_miss(Client& client, const FrameMatrix& frames, int frame, float push, size_t axis = 1) {
  const KeyPoints keys = client.describe_key_points(kModel);
  std::vector<float> full(frames.row(frame).data(), frames.row(frame).data() + frames.cols());
  for (size_t i = 0; i < full.size(); i += 3) full[i + axis] += push * static_cast<float>(i % 7);
  const std::vector<float> values = keys.gather(full);
  const PoseResult r = client.evaluate_key_points(kModel, {values, 3}, {.version = keys.model_version});
  ASSERT_NE(r.status, v1::CACHE_STATUS_HIT);
  ASSERT_TRUE(client.complete_miss(kModel, r.model_version, {values, 3}, full).logged);
}

bool wait_for_default_version(Client& client, uint64_t version) {
  return testing::wait_until([&] { return client.describe_model(kModel).default_version() == version; },
                             std::chrono::seconds(30), std::chrono::milliseconds(20));
}

TEST(RetrainOffline, FoldsEveryReplicasMissesOnceAndReplicasPickTheVersionUp) {
  TempDir repo, logs, scratch;
  ASSERT_TRUE(testing::write_demo_repository(repo.path()).ok());
  auto original = container::read_file(repo.path() / kModel / "1" / "model.anim");
  ASSERT_TRUE(original.ok());
  auto trained_frames = original->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(trained_frames.ok());
  auto arm = container::read_file(repo.path() / "arm" / "1" / "model.anim");
  ASSERT_TRUE(arm.ok());
  auto frames = arm->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());

  std::vector<Replica> replicas;
  for (const char* name : {"replica-a", "replica-b"}) {
    std::filesystem::create_directories(logs.path() / name);
    std::filesystem::create_directories(scratch.path() / name);
    auto daemon = std::make_unique<DaemonProcess>(
        std::vector<std::string>{"--model-repository", repo.path().string(), "--miss-log-dir",
                                 (logs.path() / name).string(), "--poll-interval-s", "1", "--renderer", "none"},
        scratch.path() / name);
    auto client = std::make_unique<Client>(daemon->address());
    ASSERT_TRUE(testing::wait_until_serving(*client));
    replicas.push_back({std::move(daemon), std::move(client)});
  }

  // Completed misses: frames bent off what was trained, their full values sent back.
  int completed = 0;
  auto complete_one = [&](Replica& replica, int frame, float push, size_t axis = 1) {
    complete_one_miss(*replica.client, *frames, frame, push, axis);
    ++completed;
  };
  complete_one(replicas[0], 3, 0.05f);
  complete_one(replicas[0], 9, 0.06f);
  complete_one(replicas[1], 15, 0.05f);

  nlohmann::json first = retrain_offline(repo.path(), logs.path(), scratch.path());
  EXPECT_EQ(first["logs"].get<int>(), 2);
  EXPECT_EQ(first["misses"].get<int>(), completed);
  EXPECT_EQ(first["skipped_without_full_values"].get<int>(), completed);
  EXPECT_EQ(first["training_frames"].get<long>(), trained_frames->rows() + completed);
  ASSERT_EQ(first["published_version"].get<uint64_t>(), 2u);
  for (auto& replica : replicas) EXPECT_TRUE(wait_for_default_version(*replica.client, 2)) << "the poll missed it";

  // The new version's training set is the old one plus exactly those misses, and it records how
  // far each log was read.
  auto published = container::read_file(repo.path() / kModel / "2" / "model.anim");
  ASSERT_TRUE(published.ok());
  // Each completed miss left two records: the evaluation's (no full values yet) and CompleteMiss's.
  EXPECT_EQ(pmsc::misses_through_log(*published, "replica-a/" + kModel + ".misses"), 4u);
  EXPECT_EQ(pmsc::misses_through_log(*published, "replica-b/" + kModel + ".misses"), 2u);

  // Nothing new: nothing published.
  nlohmann::json second = retrain_offline(repo.path(), logs.path(), scratch.path());
  EXPECT_EQ(second["misses"].get<int>(), 0);
  EXPECT_TRUE(second["published_version"].is_null());
  EXPECT_FALSE(std::filesystem::exists(repo.path() / kModel / "3"));
  // Not even when any number of misses will do: with the options version 2 was trained with, a
  // retrain would train on its own frames again and publish a copy of it.
  nlohmann::json forced = retrain_offline(repo.path(), logs.path(), scratch.path(), " --min-misses 0");
  EXPECT_TRUE(forced["published_version"].is_null()) << forced;
  EXPECT_NE(forced.value("reason", "").find("would publish a copy"), std::string::npos) << forced;
  EXPECT_FALSE(std::filesystem::exists(repo.path() / kModel / "3"));

  // One more miss on replica b (against version 2 now): folded in once, on top of version 2.
  complete_one(replicas[1], 21, 0.07f, 2);
  nlohmann::json third = retrain_offline(repo.path(), logs.path(), scratch.path());
  EXPECT_EQ(third["misses"].get<int>(), 1);
  EXPECT_EQ(third["from_version"].get<int>(), 2);
  EXPECT_EQ(third["training_frames"].get<long>(), trained_frames->rows() + completed);
  EXPECT_EQ(third["published_version"].get<uint64_t>(), 3u);
  // No staging directory left behind for a poll to trip over.
  for (const auto& entry : std::filesystem::directory_iterator(repo.path() / kModel)) {
    EXPECT_NE(entry.path().filename().string().rfind(".publish-", 0), 0u) << entry.path();
  }
}

// Issue #53 item 5, the step before Kubernetes (docs/DEPLOY.md maps it to deploy/): three replicas
// on loopback share one repository, each logging its own misses; one client balances round-robin
// over the three (gRPC's round_robin, with the retry policy docs/DEPLOY.md gives) and plays poses
// pinned to a version, as coordinates it reconstructs itself. Through the nightly job
// (retrain-offline folding all three logs into version 2) and each replica's swap at its poll,
// every answer names the version it was pinned to and is reconstructed with that version's basis
// (checked against the version's file, computed here); a replica killed with SIGKILL under a
// stream ends that stream only: the client's next calls are answered by the others, and the
// misses the killed replica acknowledged are all in its log.
TEST(RetrainOffline, ThreeReplicasSwapVersionsUnderARoundRobinClientAndSurviveAKill) {
  TempDir repo, logs, scratch;
  ASSERT_TRUE(testing::write_demo_repository(repo.path()).ok());
  auto arm = container::read_file(repo.path() / "arm" / "1" / "model.anim");
  ASSERT_TRUE(arm.ok());
  auto frames = arm->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());

  struct Served {
    Replica replica;
    std::string name;
    int metrics_port = 0;
    int acknowledged = 0;  // completed misses it answered `logged`
  };
  std::vector<Served> replicas;
  std::string targets;
  for (const char* name : {"replica-a", "replica-b", "replica-c"}) {
    std::filesystem::create_directories(logs.path() / name);
    std::filesystem::create_directories(scratch.path() / name);
    const int metrics_port = testing::free_tcp_port();
    auto daemon = std::make_unique<DaemonProcess>(
        std::vector<std::string>{"--model-repository", repo.path().string(), "--miss-log-dir",
                                 (logs.path() / name).string(), "--poll-interval-s", "0.2", "--renderer", "none",
                                 "--metrics-listen", "127.0.0.1:" + std::to_string(metrics_port)},
        scratch.path() / name);
    auto client = std::make_unique<Client>(daemon->address());
    ASSERT_TRUE(testing::wait_until_serving(*client));
    targets += (targets.empty() ? "ipv4:" : ",") + daemon->address();
    replicas.push_back({{std::move(daemon), std::move(client)}, name, metrics_port, 0});
  }
  for (Served& served : replicas) {
    complete_one_miss(*served.replica.client, *frames, 3, 0.05f);
    ++served.acknowledged;
  }

  grpc::ChannelArguments args;
  args.SetLoadBalancingPolicyName("round_robin");
  args.SetServiceConfigJSON(kRoundRobinRetries);
  Client balanced(grpc::CreateCustomChannel(targets, grpc::InsecureChannelCredentials(), args));

  // The player: frame after frame, pinned to `pin`, answered as coordinates and reconstructed.
  std::atomic<uint64_t> pin{1};
  std::atomic<bool> stop{false};
  std::atomic<long> answered[3] = {0, 0, 0};  // by version
  std::mutex failures_mutex;
  std::vector<std::string> failures;
  std::atomic<bool> failed{false};
  const auto fail = [&](const std::string& what) {
    std::lock_guard lock(failures_mutex);
    failures.push_back(what);
    failed = true;
  };
  BasisCache bases("");  // in memory: fetched from whichever replica answers GetBasis
  std::thread player([&] {
    std::map<uint64_t, pmsc::PmscModel> files;  // each version's model, read from the repository
    uint64_t version = 0;
    KeyPoints keys;
    for (long f = 0; !stop.load(); ++f) {
      try {
        if (pin.load() != version) {
          version = pin.load();
          keys = balanced.describe_key_points(kModel, version);
          auto file = container::read_file(repo.path() / kModel / std::to_string(version) / "model.anim");
          auto model = file.ok() ? pmsc::load(*file, kModel) : Result<pmsc::PmscModel>(file.error());
          if (!model.ok() || !pmsc::prepare_projection(*model).ok()) return fail("version " + std::to_string(version));
          files[version] = std::move(*model);
        }
        const auto row = frames->row(f % frames->rows());
        const std::vector<float> full(row.data(), row.data() + row.size());
        const std::vector<float> values = keys.gather(full), checks = keys.gather_check_values(full);
        PoseResult r = balanced.evaluate_key_points(
            kModel, {values, 3, nullptr, {}, checks},
            {.version = version, .points_encoding = v1::POINT_ENCODING_COORDINATES});
        if (r.model_version != version) {
          fail("frame " + std::to_string(f) + ": answered by version " + std::to_string(r.model_version) +
               ", pinned to " + std::to_string(version));
        }
        if (bases.reconstruct(balanced, kModel, r)) {
          pmsc::PoseEstimate expected;
          pmsc::evaluate(files.at(version), Eigen::Map<const Eigen::VectorXf>(values.data(), values.size()), expected);
          const float scale = expected.points.cwiseAbs().maxCoeff();
          const Eigen::Map<const Eigen::VectorXf> got(r.points.values.data(), static_cast<long>(r.points.values.size()));
          if (got.size() != expected.points.size() || (got - expected.points).cwiseAbs().maxCoeff() > 1e-4f * scale) {
            fail("frame " + std::to_string(f) + ": not version " + std::to_string(version) + "'s reconstruction");
          }
        }
        ++answered[version];
      } catch (const std::exception& e) {
        fail("frame " + std::to_string(f) + ": " + e.what());
      }
    }
  });
  const auto wait_for_answers = [&](uint64_t version, long count) {
    return testing::wait_until([&] { return answered[version].load() >= count || failed.load(); });
  };

  // Version 1 everywhere; then the nightly job folds every replica's log into version 2, and each
  // replica swaps it in at its poll; the player moves to it once every replica serves it.
  EXPECT_TRUE(wait_for_answers(1, 30));
  const nlohmann::json retrained = retrain_offline(repo.path(), logs.path(), scratch.path());
  EXPECT_EQ(retrained["logs"].get<int>(), 3);
  EXPECT_EQ(retrained["misses"].get<int>(), 3);
  ASSERT_EQ(retrained["published_version"].get<uint64_t>(), 2u);
  EXPECT_TRUE(wait_for_answers(1, 60)) << "the player kept going through the publish";
  for (Served& served : replicas) {
    EXPECT_TRUE(wait_for_default_version(*served.replica.client, 2)) << served.name << " never swapped";
  }
  pin = 2;
  EXPECT_TRUE(wait_for_answers(2, 30));
  stop = true;
  player.join();
  for (const std::string& failure : failures) ADD_FAILURE() << failure;
  EXPECT_GE(answered[1].load(), 60);
  EXPECT_GE(answered[2].load(), 30);

  // A stream through the balancer lands on one replica: the one with a call in flight.
  const KeyPoints keys = balanced.describe_key_points(kModel, 2);
  const auto pose_of = [&](long f) {
    const auto row = frames->row(f % frames->rows());
    return keys.gather(std::vector<float>(row.data(), row.data() + row.size()));
  };
  auto stream = balanced.open_stream(kModel, {.version = 2, .window = 1});
  const std::vector<float> first = pose_of(0);
  ASSERT_TRUE(stream->write({first, 3}, 0));
  ASSERT_TRUE(stream->read().has_value());
  Served* carrier = nullptr;
  ASSERT_TRUE(testing::wait_until([&] {
    for (Served& served : replicas) {
      const auto page = testing::scrape_metrics(served.metrics_port);
      if (page && testing::metric_value(*page, "animspace_calls_in_flight").value_or(0) >= 1) carrier = &served;
    }
    return carrier != nullptr;
  }));
  // One more acknowledged miss on it (pushed along z: unlike what version 2 learned), then SIGKILL.
  complete_one_miss(*carrier->replica.client, *frames, 21, 0.07f, 2);
  ASSERT_FALSE(HasFatalFailure());
  ++carrier->acknowledged;
  carrier->replica.daemon->send_signal(SIGKILL);
  EXPECT_NE(carrier->replica.daemon->wait_for_exit(std::chrono::seconds(30)), -1);

  // The stream ends with the replica (its next frame finds the connection gone) ...
  const std::vector<float> second = pose_of(1);
  if (stream->write({second, 3}, 1)) {
    EXPECT_FALSE(stream->read().has_value());
  }
  EXPECT_THROW(stream->finish(), RpcError);
  // ... and the client's next calls, unary and streamed, are answered by the other two.
  for (long f = 0; f < 20; ++f) {
    const std::vector<float> values = pose_of(f);
    EXPECT_EQ(balanced.evaluate_key_points(kModel, {values, 3}, {.version = 2}).model_version, 2u) << "frame " << f;
  }
  auto next = balanced.open_stream(kModel, {.version = 2});
  for (uint64_t f = 0; f < 5; ++f) {
    const std::vector<float> values = pose_of(static_cast<long>(f));
    ASSERT_TRUE(next->write({values, 3}, f));
    const auto answer = next->read();
    ASSERT_TRUE(answer.has_value());
    EXPECT_EQ(answer->model_version, 2u);
  }
  next->writes_done();
  EXPECT_FALSE(next->read().has_value());
  next->finish();

  // Nothing it acknowledged is lost: each completion it answered `logged` is in its log.
  auto records = misslog::read_records(logs.path() / carrier->name / (kModel + ".misses"), 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  int completions = 0;
  for (const auto& record : *records) completions += record.full_values.empty() ? 0 : 1;
  EXPECT_EQ(completions, carrier->acknowledged) << carrier->name;
}

}  // namespace
}  // namespace animspace
