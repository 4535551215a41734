// load_sequence's refusals name what is read and how to convert (issue #39: an Alembic cache got
// "a reference mesh needs a point cache").
#include "core/mesh_io/sequence_io.h"

#include <gtest/gtest.h>

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
  auto loaded = load_sequence("reference.obj");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("needs a point cache (.pc2)"), std::string::npos);
  EXPECT_NE(loaded.error().message.find("a folder of OBJ frames"), std::string::npos);
}

}  // namespace
}  // namespace animspace::mesh_io
