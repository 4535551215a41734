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

}  // namespace
}  // namespace animspace::model
