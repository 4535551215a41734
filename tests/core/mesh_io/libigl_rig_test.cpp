#include "core/mesh_io/libigl_rig.h"

#include <bit>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::TempDir;
using animspace::testing::write_text_file;

// Doubles that a printf("%g")-style writer would not bring back exactly.
Eigen::MatrixXd awkward_matrix(Eigen::Index rows, Eigen::Index cols) {
  const double values[] = {0.1, 1.0 / 3.0, -1e-300, -0.0, std::numeric_limits<double>::denorm_min(),
                           std::numeric_limits<double>::max(), 2.0 / 7.0 * 1e10, -123456789.123456789};
  Eigen::MatrixXd matrix(rows, cols);
  for (Eigen::Index i = 0; i < matrix.size(); ++i) matrix.data()[i] = values[i % 8] / static_cast<double>(1 + i / 8);
  return matrix;
}

template <typename Derived>
void expect_same_bits(const Eigen::MatrixBase<Derived>& expected, const Eigen::MatrixBase<Derived>& actual) {
  ASSERT_EQ(expected.rows(), actual.rows());
  ASSERT_EQ(expected.cols(), actual.cols());
  for (Eigen::Index j = 0; j < expected.cols(); ++j) {
    for (Eigen::Index i = 0; i < expected.rows(); ++i) {
      EXPECT_EQ(std::bit_cast<uint64_t>(expected(i, j)), std::bit_cast<uint64_t>(actual(i, j)))
          << "(" << i << ", " << j << "): expected " << expected(i, j) << ", got " << actual(i, j);
    }
  }
}

struct BadText {
  const char* name;
  const char* text;
  const char* message;  // after "<file>"
};

// ---- DMAT ----

TEST(DmatRead, HandWrittenIsColumnMajorWithColsFirst) {
  TempDir dir;
  // Header `cols rows` = 2 3: a 3×2 matrix, column 0 first. Line breaks do not matter.
  write_text_file(dir / "w.dmat", "2 3\n1\n2\n3\n4 5\n  6  \n");
  const auto matrix = read_dmat(dir / "w.dmat");
  ASSERT_TRUE(matrix.ok()) << matrix.error().message;
  Eigen::MatrixXd expected(3, 2);
  expected << 1, 4, 2, 5, 3, 6;
  EXPECT_EQ(*matrix, expected);
}

TEST(DmatRead, BinaryVariant) {
  TempDir dir;
  // libigl's writeDMAT(…, ascii=false): "0 0", then "cols rows", then float64 column-major.
  const double values[] = {1.5, -2.0, 0.1, 4.0, 1e-300, 6.0};
  std::string bytes = "0 0\n2 3\n";
  bytes.append(reinterpret_cast<const char*>(values), sizeof(values));
  write_text_file(dir / "w.dmat", bytes);
  const auto matrix = read_dmat(dir / "w.dmat");
  ASSERT_TRUE(matrix.ok()) << matrix.error().message;
  Eigen::MatrixXd expected(3, 2);
  expected << 1.5, 4.0, -2.0, 1e-300, 0.1, 6.0;
  EXPECT_EQ(*matrix, expected);

  write_text_file(dir / "short.dmat", bytes.substr(0, bytes.size() - 3));
  const auto truncated = read_dmat(dir / "short.dmat");
  ASSERT_FALSE(truncated.ok());
  EXPECT_EQ(truncated.error().code, ErrorCode::kDataLoss);
  EXPECT_NE(truncated.error().message.find((dir / "short.dmat").string() + ": byte 8: 3 × 2 float64 values need 6 × 8 bytes, got 45"),
            std::string::npos)
      << truncated.error().message;
}

TEST(DmatFile, RoundTripIsBitExact) {
  TempDir dir;
  for (const auto& [rows, cols] : {std::pair{5, 3}, std::pair{1, 1}, std::pair{0, 4}, std::pair{0, 0}}) {
    const Eigen::MatrixXd matrix = awkward_matrix(rows, cols);
    ASSERT_TRUE(write_dmat(dir / "m.dmat", matrix).ok());
    const auto read = read_dmat(dir / "m.dmat");
    ASSERT_TRUE(read.ok()) << read.error().message;
    expect_same_bits(matrix, *read);
  }
}

TEST(DmatFile, WriteRefusesNonFinite) {
  TempDir dir;
  Eigen::MatrixXd matrix = awkward_matrix(2, 2);
  matrix(1, 0) = std::numeric_limits<double>::infinity();
  const Status written = write_dmat(dir / "m.dmat", matrix);
  ASSERT_FALSE(written.ok());
  EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(written.error().message.find("(1, 0)"), std::string::npos) << written.error().message;
}

class DmatReadErrors : public ::testing::TestWithParam<BadText> {};

TEST_P(DmatReadErrors, NameFileAndLine) {
  TempDir dir;
  const auto path = dir / "w.dmat";
  write_text_file(path, GetParam().text);
  const auto matrix = read_dmat(path);
  ASSERT_FALSE(matrix.ok());
  EXPECT_EQ(matrix.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(matrix.error().message.find(path.string() + GetParam().message), std::string::npos)
      << matrix.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, DmatReadErrors,
    ::testing::Values(
        BadText{"Empty", "", ": empty file, expected `cols rows`"},
        BadText{"HeaderMissingRows", "3\n1\n", ":1: expected a row count, got end of line"},
        BadText{"HeaderExtra", "1 1 1\n5\n", ":1: expected end of line after `cols rows`, got '1'"},
        BadText{"NegativeCount", "-1 2\n", ":1: expected non-negative `cols rows`"},
        BadText{"TooFewValues", "2 3\n1\n2\n3\n4\n5\n",
                ":6: expected 6 values (3 rows × 2 columns, column-major), got end of file after 5"},
        BadText{"TooManyValues", "1 2\n1\n2\n3\n", ":4: expected end of file after 2 values, got '3'"},
        BadText{"BadValue", "1 2\n1\n0x2\n", ":3: expected a number, got '0x2'"},
        BadText{"NanValue", "1 2\n1\nnan\n", ":3: expected a number, got 'nan'"},
        BadText{"HugeHeader", "100000 100000\n1\n", ":1: expected at most 16 values for a file of that size"}),
    [](const auto& test) { return std::string(test.param.name); });

// ---- TGF ----

TEST(TgfRead, HandWrittenWithLibiglExtrasAndAThirdSection) {
  TempDir dir;
  write_text_file(dir / "s.tgf",
                  "   1 0.5 1 -2   \n"
                  "   2 0 3.25 0\r\n"
                  "   3 1e-3 0 7\n"
                  "#\n"
                  "   1    2 1 0 0 0\n"  // libigl's edge flags after the joints
                  "   2 3  \n"
                  "\n"
                  "#\n"
                  "1 2 3\n");  // third section (faces in some writers): ignored, as by libigl
  const auto skeleton = read_tgf(dir / "s.tgf");
  ASSERT_TRUE(skeleton.ok()) << skeleton.error().message;
  Eigen::MatrixX3d joints(3, 3);
  joints << 0.5, 1, -2, 0, 3.25, 0, 1e-3, 0, 7;
  EXPECT_EQ(skeleton->joints, joints);
  Eigen::MatrixX2i bones(2, 2);
  bones << 0, 1, 1, 2;
  EXPECT_EQ(skeleton->bones, bones);
}

TEST(TgfFile, RoundTripIsBitExact) {
  TempDir dir;
  TgfSkeleton skeleton;
  skeleton.joints = awkward_matrix(4, 3);
  skeleton.bones.resize(3, 2);
  skeleton.bones << 0, 1, 1, 2, 1, 3;
  ASSERT_TRUE(write_tgf(dir / "s.tgf", skeleton).ok());
  const auto read = read_tgf(dir / "s.tgf");
  ASSERT_TRUE(read.ok()) << read.error().message;
  expect_same_bits(skeleton.joints, read->joints);
  EXPECT_EQ(read->bones, skeleton.bones);
}

TEST(TgfFile, WriteRefusesWhatReadWouldRefuse) {
  TempDir dir;
  TgfSkeleton outside;
  outside.joints = awkward_matrix(2, 3);
  outside.bones.resize(1, 2);
  outside.bones << 0, 2;
  TgfSkeleton self_bone = outside;
  self_bone.bones << 1, 1;
  TgfSkeleton no_joints;
  TgfSkeleton not_finite = outside;
  not_finite.bones << 0, 1;
  not_finite.joints(1, 2) = std::numeric_limits<double>::quiet_NaN();
  for (const TgfSkeleton* skeleton : {&outside, &self_bone, &no_joints, &not_finite}) {
    const Status written = write_tgf(dir / "s.tgf", *skeleton);
    ASSERT_FALSE(written.ok());
    EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(written.error().message.find("s.tgf"), std::string::npos) << written.error().message;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "s.tgf"));
}

class TgfReadErrors : public ::testing::TestWithParam<BadText> {};

TEST_P(TgfReadErrors, NameFileAndLine) {
  TempDir dir;
  const auto path = dir / "s.tgf";
  write_text_file(path, GetParam().text);
  const auto skeleton = read_tgf(path);
  ASSERT_FALSE(skeleton.ok());
  EXPECT_EQ(skeleton.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(skeleton.error().message.find(path.string() + GetParam().message), std::string::npos)
      << skeleton.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, TgfReadErrors,
    ::testing::Values(
        BadText{"IndexOutOfOrder", "1 0 0 0\n3 0 0 0\n#\n", ":2: expected joint index 2, got '3'"},
        BadText{"MissingCoordinate", "1 0 0\n#\n", ":1: expected a joint coordinate, got end of line"},
        BadText{"BadCoordinate", "1 0 0 zero\n#\n", ":1: expected a joint coordinate, got 'zero'"},
        BadText{"ExtraJointColumn", "1 0 0 0 0\n#\n", ":1: expected end of line after `index x y z`, got '0'"},
        BadText{"ChildOutOfRange", "1 0 0 0\n2 1 0 0\n#\n1 3\n#\n",
                ":4: expected a joint index in 1..2 (child), got '3'"},
        BadText{"ParentZero", "1 0 0 0\n2 1 0 0\n#\n0 1\n#\n", ":4: expected a joint index in 1..2 (parent), got '0'"},
        BadText{"OneColumnBone", "1 0 0 0\n2 1 0 0\n#\n1\n#\n", ":4: expected a joint index in 1..2, got end of line"},
        BadText{"SelfBone", "1 0 0 0\n2 1 0 0\n#\n2 2\n#\n", ":4: expected a child joint other than the parent"},
        BadText{"NoJoints", "#\n#\n", ": no joints"}),
    [](const auto& test) { return std::string(test.param.name); });

// ---- Tmat ----

TEST(TmatRead, HandWrittenBlocksOfFourRows) {
  TempDir dir;
  write_text_file(dir / "p.Tmat",
                  "1 0 0\n0 1 0\n0 0 1\n10 20 30\n"
                  "  0.5 -1 0  \n1 0.5 0\n0 0 2\n-1 -2 -3\n");
  const auto transforms = read_tmat(dir / "p.Tmat");
  ASSERT_TRUE(transforms.ok()) << transforms.error().message;
  ASSERT_EQ(transforms->size(), 2u);
  Eigen::Matrix<double, 4, 3> first;
  first << 1, 0, 0, 0, 1, 0, 0, 0, 1, 10, 20, 30;
  Eigen::Matrix<double, 4, 3> second;
  second << 0.5, -1, 0, 1, 0.5, 0, 0, 0, 2, -1, -2, -3;
  EXPECT_EQ((*transforms)[0], first);
  EXPECT_EQ((*transforms)[1], second);
  // Row-vector form: [v 1] · T translates by the last row.
  const Eigen::RowVector4d v(1, 2, 3, 1);
  EXPECT_EQ(v * (*transforms)[0], Eigen::RowVector3d(11, 22, 33));
}

TEST(TmatFile, RoundTripIsBitExact) {
  TempDir dir;
  std::vector<Eigen::Matrix<double, 4, 3>> transforms(3);
  const Eigen::MatrixXd values = awkward_matrix(12, 3);
  for (int bone = 0; bone < 3; ++bone) transforms[bone] = values.middleRows(4 * bone, 4);
  ASSERT_TRUE(write_tmat(dir / "p.Tmat", transforms).ok());
  const auto read = read_tmat(dir / "p.Tmat");
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->size(), transforms.size());
  for (size_t bone = 0; bone < transforms.size(); ++bone) expect_same_bits(transforms[bone], (*read)[bone]);

  const Status empty = write_tmat(dir / "empty.Tmat", {});
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().code, ErrorCode::kInvalidArgument);
}

class TmatReadErrors : public ::testing::TestWithParam<BadText> {};

TEST_P(TmatReadErrors, NameFileAndLine) {
  TempDir dir;
  const auto path = dir / "p.Tmat";
  write_text_file(path, GetParam().text);
  const auto transforms = read_tmat(path);
  ASSERT_FALSE(transforms.ok());
  EXPECT_EQ(transforms.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(transforms.error().message.find(path.string() + GetParam().message), std::string::npos)
      << transforms.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, TmatReadErrors,
    ::testing::Values(
        BadText{"TwoValues", "1 0 0\n0 1\n", ":2: expected 3 numbers per row, got end of line"},
        BadText{"FourValues", "1 0 0 0\n", ":1: expected end of line after 3 numbers, got '0'"},
        BadText{"BadValue", "1 0 0\n0 1 0\n0 0 one\n", ":3: expected 3 numbers per row, got 'one'"},
        BadText{"SevenRows", "1 0 0\n0 1 0\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n",
                ": expected a positive multiple of 4 rows (4 per bone), got 7"},
        BadText{"Empty", "\n", ": expected a positive multiple of 4 rows (4 per bone), got 0"}),
    [](const auto& test) { return std::string(test.param.name); });

TEST(TmatFile, MissingFileIsNotFound) {
  TempDir dir;
  const auto transforms = read_tmat(dir / "absent.Tmat");
  ASSERT_FALSE(transforms.ok());
  EXPECT_EQ(transforms.error().code, ErrorCode::kNotFound);
}

}  // namespace
}  // namespace animspace::mesh_io
