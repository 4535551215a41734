#include "core/common/nearest_names.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace animspace {
namespace {

TEST(NearestNames, TyposFindTheNameOtherModelsDoNot) {
  const std::vector<std::string> served = {"arm", "arm-pmsc", "crane", "horse-gallop"};
  // A swap of neighbours is one edit: "crnae" is one step from "crane".
  EXPECT_EQ(nearest_names("crnae", served), std::vector<std::string>{"crane"});
  EXPECT_EQ(nearest_names("arm-pmcs", served), std::vector<std::string>{"arm-pmsc"});
  EXPECT_EQ(nearest_names("horse_galop", served), std::vector<std::string>{"horse-gallop"});
  EXPECT_EQ(nearest_names("am", served), (std::vector<std::string>{"arm"}));
  // Nearest first, then the candidates' order for ties.
  EXPECT_EQ(nearest_names("arm-pms", {"arm-pmsc", "arm-pm", "arm"}),
            (std::vector<std::string>{"arm-pmsc", "arm-pm"}));
  EXPECT_TRUE(nearest_names("zebra", served).empty());
  EXPECT_TRUE(nearest_names("crane", {}).empty());
  // At most three.
  EXPECT_EQ(nearest_names("m", {"a", "b", "c", "d"}).size(), 3u);
}

}  // namespace
}  // namespace animspace
