#include "server/model_registry.h"

#include <sys/stat.h>

#include <condition_variable>
#include <future>
#include <limits>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::server {
namespace {

container::ModelContainer point_model(int points) {
  container::ModelContainer model;
  model.metadata()["kind"] = "mesh_sequence";
  model.set_points("mesh.rest_points", PointMatrix::Zero(points, 3));
  return model;
}

void put(const std::filesystem::path& repo, const std::string& name, const std::string& version,
         const container::ModelContainer& model) {
  std::filesystem::create_directories(repo / name / version);
  ASSERT_TRUE(container::write_file(repo / name / version / kModelFileName, model).ok());
}

TEST(ValidateModelName, AcceptsOrdinaryNamesAndRefusesEscapes) {
  for (const char* ok : {"arm", "horse-gallop", "crane_v2", "a.b", "X1"}) {
    EXPECT_TRUE(validate_model_name(ok).ok()) << ok;
  }
  for (const char* bad : {"", ".", "..", "../x", "a/b", "a\\b", ".hidden", "a b", "a\nb"}) {
    auto status = validate_model_name(bad);
    ASSERT_FALSE(status.ok()) << bad;
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(status.error().message.find("model.name"), std::string::npos);
  }
  EXPECT_FALSE(validate_model_name(std::string(129, 'a')).ok());
  EXPECT_TRUE(validate_model_name(std::string(128, 'a')).ok());
}

// Issue #54: a FIFO named model.anim (which hung start-up) and a model file reached through a
// link out of the repository are refused with their reasons; the good model loads beside them.
TEST(ModelRegistry, FifosAndLinksOutOfTheRepositoryAreRefused) {
  testing::TempDir repo, elsewhere;
  put(repo.path(), "good", "1", point_model(3));
  std::filesystem::create_directories(repo.path() / "fifo" / "1");
  ASSERT_EQ(::mkfifo((repo.path() / "fifo" / "1" / kModelFileName).c_str(), 0600), 0);
  put(elsewhere.path(), "outside", "1", point_model(4));
  std::filesystem::create_directory_symlink(elsewhere.path() / "outside", repo.path() / "linked");

  ModelRegistry registry(repo.path());
  EXPECT_EQ(registry.load_all(), 1);
  EXPECT_TRUE(registry.find("good", 0).ok());
  auto fifo = registry.describe("fifo");
  ASSERT_TRUE(fifo.ok());
  EXPECT_NE(fifo->versions.at(1).error.find("is a FIFO, not a regular file"), std::string::npos)
      << fifo->versions.at(1).error;
  auto linked = registry.describe("linked");
  ASSERT_TRUE(linked.ok());
  EXPECT_NE(linked->versions.at(1).error.find("outside the repository"), std::string::npos)
      << linked->versions.at(1).error;
}

TEST(ModelRegistry, LoadsEveryVersionAndServesTheNewestByDefault) {
  testing::TempDir repo;
  put(repo.path(), "m", "1", point_model(3));
  put(repo.path(), "m", "10", point_model(5));  // numeric, not lexical, order: 10 > 2
  put(repo.path(), "m", "2", point_model(4));
  std::filesystem::create_directories(repo.path() / "m" / "latest");  // not a version: ignored
  std::filesystem::create_directories(repo.path() / "m" / "007");     // leading zero: ignored

  ModelRegistry registry(repo.path());
  EXPECT_EQ(registry.load_all(), 3);
  auto newest = registry.find("m", 0);
  ASSERT_TRUE(newest.ok());
  EXPECT_EQ((*newest)->version, 10u);
  EXPECT_EQ((*newest)->info.point_count, 5);
  auto two = registry.find("m", 2);
  ASSERT_TRUE(two.ok());
  EXPECT_EQ((*two)->info.point_count, 4);

  auto missing = registry.find("m", 3);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  EXPECT_NE(missing.error().message.find("available: 1, 2, 10"), std::string::npos) << missing.error().message;
}

TEST(ModelRegistry, ARefusedVersionNeverReplacesAServingOne) {
  testing::TempDir repo;
  put(repo.path(), "m", "1", point_model(3));
  ModelRegistry registry(repo.path());
  ASSERT_EQ(registry.load_all(), 1);
  auto before = registry.find("m", 1);
  ASSERT_TRUE(before.ok());

  // The file of the serving version is corrupted on disk and reloaded explicitly.
  testing::write_text_file(repo.path() / "m" / "1" / kModelFileName, "garbage");
  auto reload = registry.load("m", 1);
  ASSERT_FALSE(reload.ok());
  auto after = registry.find("m", 1);
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->get(), before->get()) << "the serving copy must be kept";

  // A new corrupt version is recorded as refused, and the default stays on version 1.
  std::filesystem::create_directories(repo.path() / "m" / "2");
  testing::write_text_file(repo.path() / "m" / "2" / kModelFileName, "garbage");
  auto all = registry.load("m", 0);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->default_version(), 1u);
  ASSERT_TRUE(all->versions.count(2));
  EXPECT_EQ(all->versions.at(2).model, nullptr);
  EXPECT_FALSE(all->versions.at(2).error.empty());
  auto refused = registry.find("m", 2);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
}

// A tool that makes a version's directory before writing its model file (the CLI writing straight
// into a served repository) can be seen by a poll in between: that poll must not write the version
// off, or it would be served only after a manual load.
TEST(ModelRegistry, AVersionFoundBeforeItsModelFileIsServedAtTheNextPoll) {
  testing::TempDir repo;
  put(repo.path(), "m", "1", point_model(3));
  ModelRegistry registry(repo.path());
  ASSERT_EQ(registry.load_all(), 1);

  std::filesystem::create_directories(repo.path() / "m" / "2");
  EXPECT_EQ(registry.load_new_versions(), 0);
  EXPECT_FALSE(registry.find("m", 2).ok());
  EXPECT_EQ((*registry.find("m", 0))->version, 1u);

  ASSERT_TRUE(container::write_file(repo.path() / "m" / "2" / kModelFileName, point_model(4)).ok());
  EXPECT_EQ(registry.load_new_versions(), 1);
  auto two = registry.find("m", 2);
  ASSERT_TRUE(two.ok()) << two.error().message;
  EXPECT_EQ((*two)->info.point_count, 4);

  // A file that is there but unreadable is refused once and not read again at every poll.
  std::filesystem::create_directories(repo.path() / "m" / "3");
  testing::write_text_file(repo.path() / "m" / "3" / kModelFileName, "garbage");
  EXPECT_EQ(registry.load_new_versions(), 0);
  auto described = registry.describe("m");
  ASSERT_TRUE(described.ok());
  ASSERT_TRUE(described->versions.count(3));
  EXPECT_FALSE(described->versions.at(3).error.empty());
  ASSERT_TRUE(container::write_file(repo.path() / "m" / "3" / kModelFileName, point_model(5)).ok());
  EXPECT_EQ(registry.load_new_versions(), 0);
}

TEST(ModelRegistry, SnapshotsOutliveUnload) {
  testing::TempDir repo;
  put(repo.path(), "m", "1", point_model(3));
  ModelRegistry registry(repo.path());
  ASSERT_EQ(registry.load_all(), 1);
  auto held = registry.find("m", 0);
  ASSERT_TRUE(held.ok());
  ASSERT_TRUE(registry.unload("m", 0).ok());
  EXPECT_EQ(registry.find("m", 0).error().code, ErrorCode::kNotFound);
  // A call in flight still holds a complete model.
  EXPECT_EQ((*held)->info.point_count, 3);
  EXPECT_EQ(registry.unload("m", 0).error().code, ErrorCode::kNotFound);
}

TEST(ModelRegistry, InconsistentSectionsAreRefusedWithTheSectionName) {
  testing::TempDir repo;
  auto model = point_model(3);
  model.set_matrix("sequence.frames", FrameMatrix(FrameMatrix::Zero(2, 8)));  // should be F×9
  put(repo.path(), "m", "1", model);
  ModelRegistry registry(repo.path());
  EXPECT_EQ(registry.load_all(), 0);
  auto entry = registry.describe("m");
  ASSERT_TRUE(entry.ok());
  const std::string& error = entry->versions.at(1).error;
  EXPECT_NE(error.find("sequence.frames"), std::string::npos) << error;
  EXPECT_NE(error.find("F×9"), std::string::npos) << error;
}

// Issue #53, --memory-budget: models of ~4 MiB each under a budget of 2.5 of them. The registry
// keeps the two most recently used and loads the third again when it is asked for.
TEST(ModelRegistry, AMemoryBudgetEvictsTheLeastRecentlyUsedAndLoadsItAgainOnRequest) {
  testing::TempDir repo;
  constexpr int kPoints = 350'000;
  const uint64_t rest_bytes = uint64_t{kPoints} * 3 * sizeof(float);
  for (const char* name : {"a", "b", "c"}) put(repo.path(), name, "1", point_model(kPoints));
  constexpr uint64_t kAllResident = std::numeric_limits<uint64_t>::max();  // every section held in memory

  {  // Without a budget every version stays, each holding at least its points.
    ModelRegistry registry(repo.path(), kAllResident);
    ASSERT_EQ(registry.load_all(), 3);
    for (const char* name : {"a", "b", "c"}) {
      auto found = registry.find(name, 0);
      ASSERT_TRUE(found.ok());
      EXPECT_GE((*found)->resident_bytes, rest_bytes) << name;
      EXPECT_LT((*found)->resident_bytes, 2 * rest_bytes) << name;
    }
    EXPECT_EQ(registry.memory().evictions, 0u);
  }

  ModelRegistry registry(repo.path(), kAllResident, rest_bytes * 5 / 2);
  ASSERT_EQ(registry.load_all(), 3);  // a, b, c in order: c's load evicts a
  const auto state = [&](const std::string& name) {
    const VersionEntry v = registry.describe(name)->versions.at(1);  // a copy: describe() returns one
    return v.model ? "loaded" : v.evicted ? "evicted" : "refused";
  };
  EXPECT_STREQ(state("a"), "evicted");
  EXPECT_STREQ(state("b"), "loaded");
  EXPECT_STREQ(state("c"), "loaded");
  const VersionEntry a = registry.describe("a")->versions.at(1);
  EXPECT_EQ(a.evicted_info.point_count, kPoints);
  EXPECT_GE(a.evicted_resident_bytes, rest_bytes);
  EXPECT_EQ(registry.describe("a")->default_version(), 1u) << "an evicted version is still served";

  ASSERT_TRUE(registry.find("b", 0).ok());  // b is now more recent than c
  auto again = registry.find("a", 0);       // a comes back; c, the least recently used, goes
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ((*again)->info.point_count, kPoints);
  EXPECT_STREQ(state("a"), "loaded");
  EXPECT_STREQ(state("b"), "loaded");
  EXPECT_STREQ(state("c"), "evicted");
  const RegistryMemory memory = registry.memory();
  EXPECT_EQ(memory.evictions, 2u);
  EXPECT_EQ(memory.reloads, 1u);
  EXPECT_LE(memory.resident_bytes, memory.budget_bytes);
  EXPECT_EQ(registry.loaded_version_count(), 2);

  // An explicit unload of an evicted version drops it for good: no reload brings it back.
  ASSERT_TRUE(registry.unload("c", 0).ok());
  EXPECT_EQ(registry.find("c", 0).error().code, ErrorCode::kNotFound);
  EXPECT_EQ(registry.memory().reloads, 1u);
}

// A budget smaller than one version serves one version at a time. While one caller loads an
// evicted version again, a second waits for that load — or, when its deadline comes first, is
// told the version is loading and how long its last load took.
TEST(ModelRegistry, ACallerWaitsForAReloadWithinItsDeadlineOrIsToldToRetry) {
  testing::TempDir repo;
  put(repo.path(), "a", "1", point_model(1000));
  put(repo.path(), "b", "1", point_model(1000));
  ModelRegistry registry(repo.path(), kDefaultResidentSectionLimit, 1);
  ASSERT_EQ(registry.load_all(), 2);
  ASSERT_TRUE(registry.describe("a")->versions.at(1).evicted);

  std::mutex mutex;
  std::condition_variable changed;
  bool loading_a = false, release = false;
  registry.set_before_load_for_testing([&](const std::string& name, uint64_t) {
    if (name != "a") return;
    std::unique_lock lock(mutex);
    loading_a = true;
    changed.notify_all();
    changed.wait(lock, [&] { return release; });
  });
  auto loader = std::async(std::launch::async, [&] { return registry.find("a", 0); });
  {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return loading_a; });
  }
  ReloadHint hint;
  auto impatient = registry.find("a", 0, std::chrono::system_clock::now() + std::chrono::milliseconds(20), &hint);
  ASSERT_FALSE(impatient.ok());
  EXPECT_NE(impatient.error().message.find("model 'a' version 1 is being loaded again"), std::string::npos)
      << impatient.error().message;
  EXPECT_NE(impatient.error().message.find("--memory-budget"), std::string::npos);
  EXPECT_GE(hint.after.count(), 1);

  auto patient = std::async(std::launch::async, [&] { return registry.find("a", 0); });
  {
    std::lock_guard lock(mutex);
    release = true;
  }
  changed.notify_all();
  auto loaded = loader.get();
  auto waited = patient.get();
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_TRUE(waited.ok()) << waited.error().message;
  EXPECT_EQ(loaded->get(), waited->get()) << "the waiting caller gets the load it waited for";
  EXPECT_EQ(registry.memory().reloads, 1u);
  EXPECT_TRUE(registry.describe("b")->versions.at(1).evicted);
}

}  // namespace
}  // namespace animspace::server
