#include "core/mesh_io/obj_sequence.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::TempDir;
using animspace::testing::write_text_file;

// A triangle whose first vertex is lifted to height `z` (one frame of an animation).
std::string frame_obj(float z, const char* faces = "f 1 2 3\nf 1 3 4\n") {
  return "v 0 0 " + std::to_string(z) + "\nv 1 0 0\nv 1 1 0\nv 0 1 0\n" + faces;
}

TEST(ObjSequence, ListsObjFilesInNaturalOrder) {
  TempDir dir;
  for (const char* name : {"frame10.obj", "frame2.obj", "frame1.obj", "frame002b.obj", "Frame3.OBJ", "notes.txt",
                           "frame11.obj.bak"}) {
    write_text_file(dir / name, frame_obj(0));
  }
  std::filesystem::create_directory(dir / "sub.obj");  // a directory, not a frame
  const auto files = list_obj_sequence(dir.path());
  ASSERT_TRUE(files.ok()) << files.error().message;
  std::vector<std::string> names;
  for (const auto& file : *files) names.push_back(file.filename().string());
  // Byte order puts 'F' before 'f'; among "frame…", 1 < 2 = 002 ("002b" after "2") < 10.
  EXPECT_EQ(names, (std::vector<std::string>{"Frame3.OBJ", "frame1.obj", "frame2.obj", "frame002b.obj", "frame10.obj"}));
}

TEST(ObjSequence, ListingErrors) {
  TempDir dir;
  const auto missing = list_obj_sequence(dir / "absent");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);

  write_text_file(dir / "readme.txt", "no frames here");
  const auto empty = list_obj_sequence(dir.path());
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().code, ErrorCode::kNotFound);
  EXPECT_NE(empty.error().message.find(dir.path().string()), std::string::npos) << empty.error().message;
}

TEST(ObjSequence, ReadsFramesIntoAPointCacheInTheGivenOrder) {
  TempDir dir;
  std::vector<std::filesystem::path> files;
  for (int k = 0; k < 3; ++k) {
    files.push_back(dir / ("f" + std::to_string(k) + ".obj"));
    write_text_file(files.back(), frame_obj(0.5f * static_cast<float>(k)));
  }
  const auto sequence = read_obj_sequence(files);
  ASSERT_TRUE(sequence.ok()) << sequence.error().message;
  FaceMatrix F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  EXPECT_EQ(sequence->F, F);
  EXPECT_EQ(sequence->frames.num_points, 4);
  EXPECT_EQ(sequence->frames.start_frame, 0.0f);
  EXPECT_EQ(sequence->frames.sample_rate, 1.0f);
  ASSERT_EQ(sequence->frames.num_frames(), 3);
  for (int k = 0; k < 3; ++k) {
    PointMatrix expected(4, 3);
    expected << 0, 0, 0.5f * static_cast<float>(k), 1, 0, 0, 1, 1, 0, 0, 1, 0;
    EXPECT_EQ(sequence->frames.frame(k), expected) << "frame " << k;
  }
}

struct BadSequence {
  const char* name;
  std::string second_frame;
  const char* message;
};

class ObjSequenceErrors : public ::testing::TestWithParam<BadSequence> {};

TEST_P(ObjSequenceErrors, NameTheFileAndWhatDiffers) {
  TempDir dir;
  const std::vector<std::filesystem::path> files = {dir / "a.obj", dir / "b.obj"};
  write_text_file(files[0], frame_obj(0));
  write_text_file(files[1], GetParam().second_frame);
  const auto sequence = read_obj_sequence(files);
  ASSERT_FALSE(sequence.ok());
  EXPECT_EQ(sequence.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(sequence.error().message.find(files[1].string()), std::string::npos) << sequence.error().message;
  EXPECT_NE(sequence.error().message.find(GetParam().message), std::string::npos) << sequence.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, ObjSequenceErrors,
    ::testing::Values(
        BadSequence{"ExtraVertex", frame_obj(1) + "v 2 2 2\n", "has 5 vertices, expected 4 as in"},
        BadSequence{"MissingTriangle", frame_obj(1, "f 1 2 3\n"), "has 1 triangles, expected 2"},
        BadSequence{"DifferentTriangle", frame_obj(1, "f 1 2 3\nf 1 3 2\n"),
                    "triangle 1 has vertices (0 2 1), expected (0 2 3)"},
        BadSequence{"ParseError", "v 0 0\n", ":1: expected a vertex coordinate"}),
    [](const auto& test) { return std::string(test.param.name); });

TEST(ObjSequence, EmptyListAndMissingFile) {
  const auto empty = read_obj_sequence({});
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().code, ErrorCode::kInvalidArgument);

  TempDir dir;
  write_text_file(dir / "a.obj", frame_obj(0));
  const auto missing = read_obj_sequence({dir / "a.obj", dir / "b.obj"});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
}

}  // namespace
}  // namespace animspace::mesh_io
