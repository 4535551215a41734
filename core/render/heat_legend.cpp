#include "core/render/heat_legend.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdio>

namespace animspace::render {
namespace {

uint8_t to_byte(float c) { return static_cast<uint8_t>(std::lround(255.0f * std::clamp(c, 0.0f, 1.0f))); }

void fill(Image& image, int x0, int y0, int x1, int y1, const std::array<uint8_t, 4>& rgba) {
  for (int y = std::max(0, y0); y < std::min(image.height, y1); ++y) {
    for (int x = std::max(0, x0); x < std::min(image.width, x1); ++x) {
      std::copy(rgba.begin(), rgba.end(), image.rgba.begin() + 4 * (static_cast<ptrdiff_t>(y) * image.width + x));
    }
  }
}

}  // namespace

Eigen::Vector3f heat_colour(float t) {
  t = 3.0f * std::clamp(t, 0.0f, 1.0f);
  const Eigen::Vector3f blue(0, 0, 1), green(0, 1, 0), yellow(1, 1, 0), red(1, 0, 0);
  if (t < 1.0f) return blue + (green - blue) * t;
  if (t < 2.0f) return green + (yellow - green) * (t - 1.0f);
  return yellow + (red - yellow) * (t - 2.0f);
}

std::array<uint8_t, 5> legend_glyph(char c) {
  switch (c) {
    case '0': return {0b111, 0b101, 0b101, 0b101, 0b111};
    case '1': return {0b010, 0b110, 0b010, 0b010, 0b111};
    case '2': return {0b111, 0b001, 0b111, 0b100, 0b111};
    case '3': return {0b111, 0b001, 0b111, 0b001, 0b111};
    case '4': return {0b101, 0b101, 0b111, 0b001, 0b001};
    case '5': return {0b111, 0b100, 0b111, 0b001, 0b111};
    case '6': return {0b111, 0b100, 0b111, 0b101, 0b111};
    case '7': return {0b111, 0b001, 0b001, 0b001, 0b001};
    case '8': return {0b111, 0b101, 0b111, 0b101, 0b111};
    case '9': return {0b111, 0b101, 0b111, 0b001, 0b111};
    case '.': return {0b000, 0b000, 0b000, 0b000, 0b010};
    case '-': return {0b000, 0b000, 0b111, 0b000, 0b000};
    case '+': return {0b000, 0b010, 0b111, 0b010, 0b000};
    case 'e': return {0b111, 0b100, 0b111, 0b100, 0b111};
    default: return {0, 0, 0, 0, 0};
  }
}

std::string legend_label(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

HeatLegendLayout heat_legend_layout(int width, int height, double heat_max) {
  HeatLegendLayout l;
  l.scale = std::max(1, std::min(width, height) / 128);
  const int s = l.scale;
  const int glyph_height = 5 * s, advance = 4 * s, pad = 2 * s, bar_width = 4 * s;
  l.labels = {legend_label(heat_max), legend_label(heat_max / 2), "0"};
  int text_width = 0;
  for (const std::string& label : l.labels) {
    text_width = std::max(text_width, static_cast<int>(label.size()) * advance - s);
  }
  const int bar_height = height / 2;
  l.bar_y0 = (height - bar_height) / 2;
  l.bar_y1 = l.bar_y0 + bar_height;
  l.panel_x1 = width - pad;
  l.panel_x0 = l.panel_x1 - (pad + bar_width + pad + text_width + pad);
  l.panel_y0 = l.bar_y0 - glyph_height / 2 - pad;
  l.panel_y1 = l.bar_y1 + glyph_height / 2 + pad;
  l.bar_x0 = l.panel_x0 + pad;
  l.bar_x1 = l.bar_x0 + bar_width;
  const int text_x = l.bar_x1 + pad;
  l.label_origin = {{{text_x, l.bar_y0 - glyph_height / 2},
                     {text_x, (l.bar_y0 + l.bar_y1 - 1) / 2 - glyph_height / 2},
                     {text_x, l.bar_y1 - 1 - glyph_height / 2}}};
  // Three labels stacked along the bar must not touch.
  l.fits = l.panel_x0 >= 0 && l.panel_y0 >= 0 && l.panel_y1 <= height && bar_height >= 3 * glyph_height;
  return l;
}

bool draw_heat_legend(Image& image, double heat_max) {
  assert(std::isfinite(heat_max) && heat_max >= 0);
  assert(image.rgba.size() == 4 * static_cast<size_t>(image.width) * static_cast<size_t>(image.height));
  const HeatLegendLayout l = heat_legend_layout(image.width, image.height, heat_max);
  if (!l.fits) return false;
  fill(image, l.panel_x0, l.panel_y0, l.panel_x1, l.panel_y1, {20, 20, 20, 255});
  const int rows = l.bar_y1 - l.bar_y0;
  for (int y = l.bar_y0; y < l.bar_y1; ++y) {
    const float t = static_cast<float>(l.bar_y1 - 1 - y) / static_cast<float>(rows - 1);
    const Eigen::Vector3f c = heat_colour(t);
    fill(image, l.bar_x0, y, l.bar_x1, y + 1, {to_byte(c.x()), to_byte(c.y()), to_byte(c.z()), 255});
  }
  const int s = l.scale;
  for (size_t k = 0; k < l.labels.size(); ++k) {
    int x = l.label_origin[k][0];
    const int y = l.label_origin[k][1];
    for (char c : l.labels[k]) {
      const auto glyph = legend_glyph(c);
      for (int row = 0; row < 5; ++row) {
        for (int column = 0; column < 3; ++column) {
          if ((glyph[static_cast<size_t>(row)] >> (2 - column)) & 1) {
            fill(image, x + column * s, y + row * s, x + (column + 1) * s, y + (row + 1) * s, {255, 255, 255, 255});
          }
        }
      }
      x += 4 * s;
    }
  }
  return true;
}

}  // namespace animspace::render
