#include "server/model_lookup.h"

#include <condition_variable>
#include <future>
#include <mutex>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::server {
namespace {

void put(const std::filesystem::path& repo, const std::string& name) {
  container::ModelContainer model;
  model.metadata()["kind"] = "mesh_sequence";
  model.set_points("mesh.rest_points", PointMatrix::Zero(3, 3));
  std::filesystem::create_directories(repo / name / "1");
  ASSERT_TRUE(container::write_file(repo / name / "1" / kModelFileName, model).ok());
}

TEST(UnknownModel, NamesTheNearestAndListsTheServedModels) {
  testing::TempDir repo;
  for (const char* name : {"arm", "arm-pmsc", "crane"}) put(repo.path(), name);
  ModelRegistry registry(repo.path());
  ASSERT_EQ(registry.load_all(), 3);

  const grpc::Status typo = unknown_model(registry, "crnae");
  EXPECT_EQ(typo.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(typo.error_message(), "model 'crnae' is not loaded; did you mean 'crane'? models: arm, arm-pmsc, crane");
  EXPECT_EQ(unknown_model(registry, "zebra").error_message(),
            "model 'zebra' is not loaded; models: arm, arm-pmsc, crane");

  // find_model answers an unknown name so; a wrong version of a known one keeps listing versions.
  std::shared_ptr<const LoadedModel> found;
  v1::ModelRef ref;
  ref.set_name("arm-pmcs");
  const grpc::Status by_name = find_model(registry, ref, "model", found);
  EXPECT_EQ(by_name.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(by_name.error_message().find("did you mean 'arm-pmsc'"), std::string::npos) << by_name.error_message();
  ref.set_name("arm");
  ref.set_version(7);
  const grpc::Status by_version = find_model(registry, ref, "model", found);
  EXPECT_EQ(by_version.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(by_version.error_message().find("available: 1"), std::string::npos) << by_version.error_message();

  testing::TempDir empty;
  ModelRegistry none(empty.path());
  ASSERT_EQ(none.load_all(), 0);
  EXPECT_EQ(unknown_model(none, "arm").error_message(), "model 'arm' is not loaded; the server serves no models");
}

// Issue #54: before the repository is loaded, a model that is not loaded may be loaded in a
// moment: UNAVAILABLE, which clients retry, not the final NOT_FOUND.
TEST(UnknownModel, IsUnavailableWhileTheRepositoryLoads) {
  testing::TempDir repo;
  put(repo.path(), "arm");
  ModelRegistry registry(repo.path());
  std::shared_ptr<const LoadedModel> found;
  v1::ModelRef ref;
  ref.set_name("arm");
  const grpc::Status early = find_model(registry, ref, "model", found);
  EXPECT_EQ(early.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(early.error_message(),
            "model 'arm' is not loaded yet: the server is still loading its repository (health NOT_SERVING); retry");
  ASSERT_EQ(registry.load_all(), 1);
  EXPECT_TRUE(find_model(registry, ref, "model", found).ok());
  ref.set_name("crane");
  EXPECT_EQ(find_model(registry, ref, "model", found).error_code(), grpc::StatusCode::NOT_FOUND);
}

// Issue #53: a request for a version being loaded again under --memory-budget, whose deadline
// comes before the load ends, gets UNAVAILABLE (which clients retry), saying why.
TEST(FindModel, IsUnavailableWhileAnEvictedVersionLoadsAgain) {
  testing::TempDir repo;
  for (const char* name : {"a", "b"}) put(repo.path(), name);
  ModelRegistry registry(repo.path(), kDefaultResidentSectionLimit, 1);  // one version at a time
  ASSERT_EQ(registry.load_all(), 2);
  std::mutex mutex;
  std::condition_variable changed;
  bool loading = false, release = false;
  registry.set_before_load_for_testing([&](const std::string& name, uint64_t) {
    if (name != "a") return;
    std::unique_lock lock(mutex);
    loading = true;
    changed.notify_all();
    changed.wait(lock, [&] { return release; });
  });
  v1::ModelRef ref;
  ref.set_name("a");
  std::shared_ptr<const LoadedModel> first;
  auto loader = std::async(std::launch::async, [&] { return find_model(registry, ref, "model", first); });
  {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return loading; });
  }
  std::shared_ptr<const LoadedModel> second;
  const grpc::Status waiting = find_model(registry, ref, "model", second, nullptr,
                                          std::chrono::system_clock::now() + std::chrono::milliseconds(20));
  EXPECT_EQ(waiting.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(waiting.error_message().find("model 'a' version 1 is being loaded again"), std::string::npos)
      << waiting.error_message();
  EXPECT_EQ(second, nullptr);
  {
    std::lock_guard lock(mutex);
    release = true;
  }
  changed.notify_all();
  EXPECT_TRUE(loader.get().ok());
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(first->name, "a");
}

}  // namespace
}  // namespace animspace::server
