// The heat map's legend drawn onto a rendered image: a colour bar from 0 (bottom, blue) to the
// scale's top (red) with its numbers, so that a reader of the thumbnail knows what red means.
//
// Drawn on the CPU after the render (any Renderer, including a test's fake one), with a built-in
// 3 × 5 bitmap font of the characters a number needs ("0123456789.-+e").
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "core/render/scene.h"

namespace animspace::render {

// The map of Scene::heat: t clamped to [0, 1], blue at 0, green at 1/3, yellow at 2/3, red at 1,
// linear in between (the shader's heat_colour in egl_renderer.cpp), RGB in [0, 1].
Eigen::Vector3f heat_colour(float t);

// A glyph of the legend's font: 5 rows of 3 bits, most significant bit the left column; all zero
// for a character the font lacks.
std::array<uint8_t, 5> legend_glyph(char c);

// The label for a value: printf "%.3g" ("0.05", "1.5e-05").
std::string legend_label(double value);

// Where the legend goes in a width × height image; pixel rectangles [x0, x1) × [y0, y1).
struct HeatLegendLayout {
  bool fits = false;    // false: the image is too small to hold it (nothing is drawn)
  int scale = 1;        // font pixels per glyph cell
  int panel_x0 = 0, panel_y0 = 0, panel_x1 = 0, panel_y1 = 0;  // dark backdrop
  int bar_x0 = 0, bar_y0 = 0, bar_x1 = 0, bar_y1 = 0;          // row bar_y1 − 1 is 0, row bar_y0 is the top
  // Top-left corners of the three labels (top of the scale, half of it, 0).
  std::array<std::array<int, 2>, 3> label_origin{};
  std::array<std::string, 3> labels;
};
HeatLegendLayout heat_legend_layout(int width, int height, double heat_max);

// Draws the legend for a scale of [0, heat_max] (heat_max ≥ 0, finite) into `image` at its right
// edge; the bar's row at height fraction t (from the bottom) is heat_colour(t) exactly, labels are
// white on a dark backdrop. Returns false, leaving the image unchanged, when it does not fit.
bool draw_heat_legend(Image& image, double heat_max);

}  // namespace animspace::render
