// Radiance drawn as colours (Meyer & Anderson 2007 Figs. 5 and 10): linear RGB radiance on a
// surface, exposed so that a chosen radiance is white, sRGB-encoded and unlit (the colours already
// are the light).
#pragma once

#include "core/common/types.h"
#include "core/render/scene.h"

namespace animspace::thumbnail {

// The radiance drawn white when none is given: the 99th percentile (the element at rank
// ⌊0.99·(N − 1)⌋ of the N points' largest channels, ascending), so that a few hot spots do not
// darken the whole picture; 1 when there are no points or that value is ≤ 0.
double radiance_white_point(const PointMatrix& colours);

// Sets the scene's colours to `radiance` (#V × 3, linear RGB, W/sr/m² or any consistent unit):
// vertex_colours = max(radiance, 0) — a reconstruction may dip a little below zero where the
// radiance is near zero; light is not negative, so the picture shows 0 there —, exposure =
// 1 / white with white = `white_radiance` when > 0, else radiance_white_point of the clamped
// colours; srgb on, shading unlit. `white_radiance` finite and ≥ 0 (asserted).
void radiance_colours(PointMatrix radiance, double white_radiance, render::Scene& scene);

}  // namespace animspace::thumbnail
