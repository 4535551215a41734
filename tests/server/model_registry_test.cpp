#include "server/model_registry.h"

#include <sys/stat.h>

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

}  // namespace
}  // namespace animspace::server
