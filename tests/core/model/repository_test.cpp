// The model repository's version folders (core/model/repository.h).
#include "core/model/repository.h"

#include <filesystem>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::model {
namespace {

// Issue #54: a publish after version 2⁶⁴ − 1 would wrap to version 0, which no loader reads.
TEST(Repository, VersionNumbersDoNotWrap) {
  testing::TempDir repository;
  const std::string largest = std::to_string(std::numeric_limits<uint64_t>::max());
  std::filesystem::create_directories(repository.path() / "arm" / "7");
  auto next = publish_version(repository.path(), "arm", container::ModelContainer());
  ASSERT_TRUE(next.ok()) << next.error().message;
  EXPECT_EQ(*next, 8u);

  std::filesystem::create_directories(repository.path() / "arm" / largest);
  const auto refused = publish_version(repository.path(), "arm", container::ModelContainer());
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kOutOfRange);
  EXPECT_NE(refused.error().message.find("already has version " + largest), std::string::npos)
      << refused.error().message;
  // Nothing was written beside the versions that were there.
  auto versions = list_versions(repository.path(), "arm");
  ASSERT_TRUE(versions.ok());
  EXPECT_EQ(versions->size(), 3u);
  for (const auto& entry : std::filesystem::directory_iterator(repository.path() / "arm")) {
    EXPECT_NE(entry.path().filename().string().rfind(".publish-", 0), 0u) << entry.path();
  }
}

// Issue #54: a model reached through a link out of the repository is refused before it is read;
// links within the repository are followed.
TEST(Repository, LinksAreFollowedOnlyWithinTheRepository) {
  testing::TempDir repository, elsewhere;
  std::filesystem::create_directories(repository.path() / "arm" / "1");
  testing::write_text_file(repository.path() / "arm" / "1" / kModelFileName, "model");
  testing::write_text_file(elsewhere.path() / "secret", "root:*:");
  EXPECT_TRUE(check_inside_repository(repository.path(), repository.path() / "arm" / "1" / kModelFileName).ok());

  // A version folder, a model folder and a model file that lead out.
  std::filesystem::create_directories(repository.path() / "crane");
  std::filesystem::create_directory_symlink(elsewhere.path(), repository.path() / "crane" / "1");
  std::filesystem::create_directory_symlink(elsewhere.path(), repository.path() / "horse");
  std::filesystem::create_directories(repository.path() / "cow" / "1");
  std::filesystem::create_symlink(elsewhere.path() / "secret", repository.path() / "cow" / "1" / kModelFileName);
  for (const auto& link : {repository.path() / "crane" / "1" / "secret", repository.path() / "horse" / "secret",
                           repository.path() / "cow" / "1" / kModelFileName}) {
    const Status refused = check_inside_repository(repository.path(), link);
    ASSERT_FALSE(refused.ok()) << link;
    EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
    EXPECT_NE(refused.error().message.find("outside the repository"), std::string::npos) << refused.error().message;
    EXPECT_EQ(refused.error().message.find("root:"), std::string::npos) << "never the file's bytes";
  }
  // A link from one model's version to another's, inside the repository, is followed.
  std::filesystem::create_directories(repository.path() / "arm-copy");
  std::filesystem::create_directory_symlink(repository.path() / "arm" / "1", repository.path() / "arm-copy" / "1");
  EXPECT_TRUE(
      check_inside_repository(repository.path(), repository.path() / "arm-copy" / "1" / kModelFileName).ok());
}

}  // namespace
}  // namespace animspace::model
