// load_sequence's refusals name what is read and how to convert (issue #39: an Alembic cache got
// "a reference mesh needs a point cache").
#include "core/mesh_io/sequence_io.h"

#include <filesystem>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

TEST(SequenceIo, CachesOfOtherToolsAreNamedWithTheWayToConvert) {
  for (const char* file : {"shot.abc", "shot.ABC", "stage.usdc", "take.fbx", "frames.mdd"}) {
    auto loaded = load_sequence(file);
    ASSERT_FALSE(loaded.ok()) << file;
    EXPECT_EQ(loaded.error().code, ErrorCode::kInvalidArgument);
    const std::string& message = loaded.error().message;
    EXPECT_NE(message.find(file), std::string::npos) << message;
    EXPECT_NE(message.find("is not read"), std::string::npos) << message;
    EXPECT_NE(message.find("reference.obj + frames.pc2"), std::string::npos) << message;
    EXPECT_NE(message.find("Blender"), std::string::npos) << message;
    EXPECT_NE(message.find("Train from animation"), std::string::npos) << message;
  }
  // As a point cache too.
  auto loaded = load_sequence("reference.obj", "frames.abc");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("Alembic"), std::string::npos) << loaded.error().message;
}

TEST(SequenceIo, AMeshWithoutItsCacheSaysWhatIsRead) {
  testing::TempDir dir;
  testing::write_text_file(dir / "reference.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  auto loaded = load_sequence(dir / "reference.obj");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("needs a point cache (.pc2)"), std::string::npos);
  EXPECT_NE(loaded.error().message.find("a folder of OBJ frames"), std::string::npos);
}

// Issue #55: a typo'd path is named as missing, with what it was probably meant to be, not
// taken for a mesh without its cache.
TEST(SequenceIo, AMissingPathIsNamedWithTheNearestNamesBesideIt) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "crane");
  testing::write_text_file(dir / "crane" / "frames.pc2", "");
  testing::write_text_file(dir / "crane" / "reference.obj", "");

  auto loaded = load_sequence(dir / "crane" / "frames.pc");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().code, ErrorCode::kNotFound);
  EXPECT_EQ(loaded.error().message, (dir / "crane" / "frames.pc").string() + ": no such file or folder; did you mean " +
                                        (dir / "crane" / "frames.pc2").string() + "?");
  loaded = load_sequence(dir / "crame");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().message,
            (dir / "crame").string() + ": no such file or folder; did you mean " + (dir / "crane").string() + "?");
  loaded = load_sequence(dir / "nowhere" / "frames.pc2");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().message, (dir / "nowhere" / "frames.pc2").string() + ": no such file or folder (nor the folder " +
                                        (dir / "nowhere").string() + ")");
  loaded = load_sequence(dir / "crane" / "reference.obj", dir / "crane" / "frame.pc2");
  ASSERT_FALSE(loaded.ok());
  EXPECT_EQ(loaded.error().code, ErrorCode::kNotFound);
  EXPECT_NE(loaded.error().message.find("did you mean " + (dir / "crane" / "frames.pc2").string()), std::string::npos);
}

}  // namespace
}  // namespace animspace::mesh_io
