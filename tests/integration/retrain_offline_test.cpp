// `animspace retrain-offline` as the nightly job of a scaled-out deployment: two replicas serve
// one repository, each logging its own misses under one root; the job folds every completed miss
// of both into the next version, publishes it atomically, and both replicas pick it up by
// polling. A second run finds nothing new (per-log watermarks); a new miss on one replica is
// folded in exactly once more.
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/container/sections.h"
#include "core/pmsc/retrain.h"
#include "harness/daemon_process.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;

const std::string kModel(demo::kDemoPmscModelName);

struct Replica {
  std::unique_ptr<DaemonProcess> daemon;
  std::unique_ptr<Client> client;
};

nlohmann::json retrain_offline(const std::filesystem::path& repo, const std::filesystem::path& logs,
                               const std::filesystem::path& scratch, const std::string& flags = "") {
  const auto out = scratch / "retrain.json";
  const std::string command = std::string(ANIMSPACE_CLI_PATH) + " --json retrain-offline --repository " +
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

bool wait_for_default_version(Client& client, uint64_t version) {
  return testing::wait_until([&] { return client.describe_model(kModel).default_version() == version; },
                             std::chrono::seconds(30), std::chrono::milliseconds(20));
}

TEST(RetrainOffline, FoldsEveryReplicasMissesOnceAndReplicasPickTheVersionUp) {
  TempDir repo, logs, scratch;
  ASSERT_TRUE(demo::write_demo_repository(repo.path()).ok());
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
  // `axis`: the coordinate pushed, so that a later miss can be unlike what the earlier taught.
  auto complete_one = [&](Replica& replica, int frame, float push, size_t axis = 1) {
    // The key points of the version served now (a retrain may choose others), pinned to it.
    const KeyPoints keys = replica.client->describe_key_points(kModel);
    std::vector<float> full(frames->row(frame).data(), frames->row(frame).data() + frames->cols());
    for (size_t i = 0; i < full.size(); i += 3) full[i + axis] += push * static_cast<float>(i % 7);
    const std::vector<float> values = keys.gather(full);
    const PoseResult r = replica.client->evaluate_key_points(kModel, {values, 3}, {.version = keys.model_version});
    ASSERT_NE(r.status, v1::CACHE_STATUS_HIT);
    ASSERT_TRUE(replica.client->complete_miss(kModel, r.model_version, {values, 3}, full).logged);
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

}  // namespace
}  // namespace animspace
