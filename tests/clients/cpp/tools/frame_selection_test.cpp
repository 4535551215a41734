#include "clients/cpp/tools/frame_selection.h"

#include <gtest/gtest.h>

namespace animspace::tools {
namespace {

FrameMatrix numbered(Eigen::Index rows, Eigen::Index cols) {
  FrameMatrix m(rows, cols);
  for (Eigen::Index r = 0; r < rows; ++r) {
    for (Eigen::Index c = 0; c < cols; ++c) m(r, c) = static_cast<float>(100 * r + c);
  }
  return m;
}

TEST(FrameSelection, SlicesCountFromTheEndAndStep) {
  std::string error;
  EXPECT_EQ(parse_frame_selection("::", 4, &error), (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(parse_frame_selection("1::2", 6, &error), (std::vector<int>{1, 3, 5}));
  EXPECT_EQ(parse_frame_selection("-2:", 5, &error), (std::vector<int>{3, 4}));
  EXPECT_EQ(parse_frame_selection("0:3", 10, &error), (std::vector<int>{0, 1, 2}));
}

// Issue #53: take_rows moves every row in order (the point cache is not held twice) and copies
// any other selection; either way the source is left empty and the rows are the selected ones.
TEST(FrameSelection, TakingEveryRowMovesTheMatrixAndAnySelectionLeavesTheSourceEmpty) {
  FrameMatrix all = numbered(5, 6);
  const float* storage = all.data();
  const FrameMatrix expected = all;
  const FrameMatrix moved = take_rows(all, {0, 1, 2, 3, 4});
  EXPECT_EQ(moved.data(), storage) << "every row in order is the matrix itself, not a copy";
  EXPECT_EQ(moved, expected);
  EXPECT_EQ(all.size(), 0);

  FrameMatrix some = numbered(5, 6);
  const FrameMatrix picked = take_rows(some, {4, 0, 2});
  ASSERT_EQ(picked.rows(), 3);
  EXPECT_EQ(picked.row(0), expected.row(4));
  EXPECT_EQ(picked.row(1), expected.row(0));
  EXPECT_EQ(picked.row(2), expected.row(2));
  EXPECT_EQ(some.size(), 0);
  EXPECT_EQ(select_rows(expected, {4, 0, 2}), picked);
}

}  // namespace
}  // namespace animspace::tools
