// A drawn thumbnail as PNG: the bytes decode to the image (with the legend, when asked for and
// when it fits, drawn over it as render::draw_heat_legend draws it), and an empty image is refused.
#include "core/thumbnail/thumbnail_png.h"

#include <gtest/gtest.h>

#include "core/render/heat_legend.h"
#include "core/render/png.h"

namespace animspace::thumbnail {
namespace {

render::Image gradient(int width, int height) {
  render::Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(static_cast<size_t>(width) * height * 4);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      uint8_t* p = image.rgba.data() + 4 * (static_cast<size_t>(y) * width + x);
      p[0] = static_cast<uint8_t>(x);
      p[1] = static_cast<uint8_t>(y);
      p[2] = static_cast<uint8_t>(x + y);
      p[3] = 255;
    }
  }
  return image;
}

std::vector<uint8_t> decoded_pixels(const std::string& png) {
  auto image = render::decode_png(png, "test");
  EXPECT_TRUE(image.ok());
  return image.ok() ? image->rgba : std::vector<uint8_t>{};
}

TEST(ThumbnailPng, WithoutALegendThePngIsTheImage) {
  const render::Image image = gradient(64, 48);
  auto encoded = encode_thumbnail(image, std::nullopt);
  ASSERT_TRUE(encoded.ok()) << encoded.error().message;
  EXPECT_FALSE(encoded->heat_legend_drawn);
  EXPECT_EQ(decoded_pixels(encoded->png), image.rgba);
}

TEST(ThumbnailPng, TheLegendIsDrawnOverTheImageWhenItFits) {
  render::Image expected = gradient(256, 200);
  ASSERT_TRUE(render::draw_heat_legend(expected, 0.25));
  auto encoded = encode_thumbnail(gradient(256, 200), 0.25);
  ASSERT_TRUE(encoded.ok()) << encoded.error().message;
  EXPECT_TRUE(encoded->heat_legend_drawn);
  EXPECT_EQ(decoded_pixels(encoded->png), expected.rgba);
  EXPECT_NE(expected.rgba, gradient(256, 200).rgba);  // the legend changed something

  // Too small to hold it: not drawn, the image unchanged.
  const render::Image tiny = gradient(4, 4);
  auto small = encode_thumbnail(tiny, 0.25);
  ASSERT_TRUE(small.ok());
  EXPECT_FALSE(small->heat_legend_drawn);
  EXPECT_EQ(decoded_pixels(small->png), tiny.rgba);
}

TEST(ThumbnailPng, AnEmptyImageIsRefused) {
  auto refused = encode_thumbnail(render::Image{}, std::nullopt);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace animspace::thumbnail
