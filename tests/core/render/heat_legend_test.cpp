#include "core/render/heat_legend.h"

#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace animspace::render {
namespace {

Image blank(int width, int height) {
  Image image;
  image.width = width;
  image.height = height;
  image.rgba.assign(4 * static_cast<size_t>(width) * static_cast<size_t>(height), 7);
  return image;
}

std::vector<uint8_t> rgb(const Image& image, int x, int y) {
  const uint8_t* p = image.pixel(x, y);
  return {p[0], p[1], p[2]};
}

// The thesis's map written out by hand (Fig. 8.6 as scene.h documents it), as 8-bit RGB.
std::vector<uint8_t> expected_colour(double t) {
  double r = 0, g = 0, b = 0;
  if (t < 1.0 / 3) {
    g = 3 * t, b = 1 - 3 * t;
  } else if (t < 2.0 / 3) {
    r = 3 * t - 1, g = 1;
  } else {
    r = 1, g = 3 - 3 * t;
  }
  return {static_cast<uint8_t>(std::lround(255 * r)), static_cast<uint8_t>(std::lround(255 * g)),
          static_cast<uint8_t>(std::lround(255 * b))};
}

TEST(HeatLegendTest, TheBarRunsFromBlueAtZeroToRedAtTheTopOfTheScale) {
  Image image = blank(256, 200);
  ASSERT_TRUE(draw_heat_legend(image, 0.05));
  const HeatLegendLayout l = heat_legend_layout(256, 200, 0.05);
  ASSERT_TRUE(l.fits);
  EXPECT_EQ(l.scale, 1);
  EXPECT_GE(l.panel_x0, 0);
  EXPECT_LE(l.panel_x1, 256);
  const int x = (l.bar_x0 + l.bar_x1) / 2;
  const int rows = l.bar_y1 - l.bar_y0;
  EXPECT_EQ(rows, 100);
  EXPECT_EQ(rgb(image, x, l.bar_y1 - 1), (std::vector<uint8_t>{0, 0, 255})) << "0 is blue";
  EXPECT_EQ(rgb(image, x, l.bar_y0), (std::vector<uint8_t>{255, 0, 0})) << "the top of the scale is red";
  for (int y = l.bar_y0; y < l.bar_y1; y += 7) {
    const double t = static_cast<double>(l.bar_y1 - 1 - y) / (rows - 1);
    const auto want = expected_colour(t);
    const auto got = rgb(image, x, y);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[static_cast<size_t>(c)], want[static_cast<size_t>(c)], 1) << "row " << y;
  }
  // Outside the panel the image is untouched.
  EXPECT_EQ(rgb(image, 0, 0), (std::vector<uint8_t>{7, 7, 7}));
  EXPECT_EQ(rgb(image, l.panel_x0 - 1, l.bar_y0), (std::vector<uint8_t>{7, 7, 7}));
}

TEST(HeatLegendTest, TheLabelsSayTheScalesNumbers) {
  EXPECT_EQ(legend_label(0.05), "0.05");
  EXPECT_EQ(legend_label(0.0012345), "0.00123");
  EXPECT_EQ(legend_label(1.5e-5), "1.5e-05");
  const HeatLegendLayout l = heat_legend_layout(512, 512, 0.05);
  ASSERT_TRUE(l.fits);
  EXPECT_EQ(l.labels[0], "0.05");
  EXPECT_EQ(l.labels[1], "0.025");
  EXPECT_EQ(l.labels[2], "0");
  EXPECT_EQ(l.scale, 4);

  // Every character a label can hold has a glyph, and no two look alike.
  std::set<std::array<uint8_t, 5>> seen;
  for (char c : std::string("0123456789.-+e")) {
    const auto glyph = legend_glyph(c);
    EXPECT_NE(glyph, (std::array<uint8_t, 5>{})) << c;
    EXPECT_TRUE(seen.insert(glyph).second) << c << " looks like another character";
  }

  // The top label is drawn cell by cell from its glyphs: white where a glyph bit is set, the
  // backdrop elsewhere.
  Image image = blank(512, 512);
  ASSERT_TRUE(draw_heat_legend(image, 0.05));
  const int s = l.scale;
  for (size_t k = 0; k < l.labels[0].size(); ++k) {
    const auto glyph = legend_glyph(l.labels[0][k]);
    for (int row = 0; row < 5; ++row) {
      for (int column = 0; column < 3; ++column) {
        const bool on = (glyph[static_cast<size_t>(row)] >> (2 - column)) & 1;
        const int x = l.label_origin[0][0] + static_cast<int>(k) * 4 * s + column * s + s / 2;
        const int y = l.label_origin[0][1] + row * s + s / 2;
        EXPECT_EQ(rgb(image, x, y), on ? (std::vector<uint8_t>{255, 255, 255}) : (std::vector<uint8_t>{20, 20, 20}))
            << "'" << l.labels[0][k] << "' row " << row << " column " << column;
      }
    }
  }
}

TEST(HeatLegendTest, AnImageTooSmallIsLeftAsItIs) {
  for (const auto& [w, h] : {std::pair{1, 1}, {16, 16}, {24, 256}}) {
    Image image = blank(w, h);
    const auto before = image.rgba;
    EXPECT_FALSE(draw_heat_legend(image, 0.05)) << w << "×" << h;
    EXPECT_EQ(image.rgba, before);
  }
  Image small = blank(64, 64);
  EXPECT_TRUE(draw_heat_legend(small, 0.05)) << "a 64-px thumbnail has room";
}

}  // namespace
}  // namespace animspace::render
