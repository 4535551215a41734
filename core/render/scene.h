// What the renderer draws: a posed triangle mesh, a camera, shading and overlays.
//
// Plain data with no GL in it, so that the server can build a scene on any thread and hand it to
// the one thread that owns the context (server/render_thread.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/types.h"

namespace animspace::render {

// A perspective camera in the model's object frame.
struct Camera {
  Eigen::Vector3d eye = Eigen::Vector3d(0, 0, 3);
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();
  double vertical_fov_rad = 0.8;  // in (0, π)
};

enum class Shading { kLambert, kBlinnPhong, kUnlit };

// Thumbnails are small and drawn once: the shading is a fixed, documented model rather than a
// material system, so that a test can compute the value of any pixel by hand.
//
// One white directional "headlight" shining from the eye along the view direction l = v =
// normalise(eye − p). With albedo a, ambient k_a, diffuse k_d, specular k_s and shininess s:
//   Lambert:      c = a · (k_a + k_d · max(n·l, 0))
//   Blinn-Phong:  c = a · (k_a + k_d · max(n·l, 0)) + k_s · max(n·h, 0)^s,  h = normalise(l + v) = l
//   Unlit:        c = a  (no light: for colours that already are radiance, e.g. precomputed
//                 indirect illumination)
// each channel clamped to [0, 1], then (Scene::srgb only) sRGB-encoded, written as 8-bit (round
// to nearest). Back faces are lit with their flipped normal (thumbnails of open meshes stay
// readable).
//
// The albedo a of a fragment is, in order of precedence (at most one of Scene::heat,
// Scene::vertex_colours and Scene::corner_uvs is set):
//   the heat colour of the interpolated heat value (Scene::heat),
//   exposure · the interpolated vertex colour (Scene::vertex_colours, Scene::exposure),
//   the checker colour of the interpolated texture coordinate (Scene::corner_uvs, Checker),
//   Material::albedo.
struct Material {
  Eigen::Vector3f albedo = Eigen::Vector3f(0.80f, 0.78f, 0.74f);
  float ambient = 0.15f;
  float diffuse = 0.85f;
  float specular = 0.25f;
  float shininess = 32;
};

// A procedural checker texture (no image) over a texture atlas, to show its stretch and seams
// (issue #37): squares that stay square across poses are what a balanced atlas buys. With (u, v)
// the fragment's interpolated texture coordinate and N = squares_per_uv, the square is
// (i, j) = (⌊N·u⌋, ⌊N·v⌋) and the albedo a is `even` when i + j is even, `odd` when it is odd:
// square (0, 0), at the atlas's origin, is `even`. The checker colour is then lit like any albedo.
struct Checker {
  float squares_per_uv = 16;  // N: squares along one unit of u (and of v); finite, > 0
  Eigen::Vector3f even = Eigen::Vector3f(0.92f, 0.92f, 0.92f);
  Eigen::Vector3f odd = Eigen::Vector3f(0.20f, 0.20f, 0.22f);
  // Lines on the atlas's seams: every edge not shared by exactly two faces that give both of its
  // ends the same texture coordinates (in an atlas: the chart borders, and the mesh's own
  // boundary). Drawn like the wireframe, on top of the surface with hidden lines hidden.
  bool chart_borders = false;
  Eigen::Vector3f chart_border_colour = Eigen::Vector3f(0.85f, 0.10f, 0.10f);
};

struct Scene {
  int width = 256;   // pixels, ≥ 1
  int height = 256;  // pixels, ≥ 1
  PointMatrix points;  // #V × 3, posed
  FaceMatrix faces;    // #F × 3, counter-clockwise seen from outside
  // Unit vertex normals (#V × 3, e.g. animation-space tangent planes, Merry 2007 §4.3), or empty:
  // area-weighted normals are computed from the faces.
  PointMatrix normals;
  // Absent: frame_bounding_box(points, width / height).
  std::optional<Camera> camera;
  Eigen::Vector4f background = Eigen::Vector4f(0.18f, 0.18f, 0.20f, 1.0f);  // RGBA in [0, 1]
  Shading shading = Shading::kBlinnPhong;
  Material material;
  int samples = 4;  // multisampling: 1, 2, 4 or 8

  // Overlays.
  // Vertices drawn as dots on top of the surface (the key points of Meyer & Anderson 2007, Fig. 1).
  std::vector<int32_t> key_points;
  float key_point_radius_px = 3.0f;
  Eigen::Vector3f key_point_colour = Eigen::Vector3f(1.0f, 0.85f, 0.1f);
  // Per-vertex values (#V, ≥ 0) drawn as a heat map instead of the albedo (thesis Fig. 8.6):
  // 0 is blue, heat_max (or the largest value when heat_max ≤ 0) is red, through green/yellow.
  // The map is piecewise linear in t = heat / heat_max clamped to [0, 1] (blue at 0, green at 1/3,
  // yellow at 2/3, red at 1), evaluated per fragment on the interpolated value, and the colour
  // replaces the albedo a in the shading model above (still lit, so the shape stays readable,
  // unless the shading is kUnlit).
  Eigen::VectorXf heat;
  float heat_max = 0;
  // Per-vertex colours (#V × 3, linear RGB, ≥ 0, any scale, e.g. the radiance of indirect
  // illumination), or empty. Interpolated per fragment and multiplied by `exposure`, they replace
  // the albedo a in the shading model above, in every shading mode: with Shading::kUnlit the pixel
  // is round(255 · clamp(exposure · colour, 0, 1)). Refused together with `heat` (one colour
  // source per surface, so neither is dropped silently).
  PointMatrix vertex_colours;
  float exposure = 1.0f;  // > 0; scales vertex_colours only (not Material::albedo nor the heat map)
  // Texture coordinates per face corner (3·#F × 2: row 3f + k is corner k of face f, finite),
  // or empty. Set, the surface is drawn with `checker` as its albedo (see Checker). Refused
  // together with `heat` or `vertex_colours`. Corners of one vertex may differ (seams): the
  // renderer draws each corner as its own vertex.
  Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor> corner_uvs;
  Checker checker;
  // Encode the surface's colour with the sRGB transfer function after clamping to [0, 1]:
  //   c ≤ 0.0031308:  12.92 · c,   otherwise  1.055 · c^(1/2.4) − 0.055
  // (IEC 61966-2-1), for linear radiance shown on a display. The background and the overlays
  // are drawn as given.
  bool srgb = false;
  // Triangle edges drawn on top of the shaded surface.
  bool wireframe = false;
  Eigen::Vector3f wireframe_colour = Eigen::Vector3f(0.05f, 0.05f, 0.05f);
};

// 8-bit RGBA, rows top to bottom (as PNG stores them).
struct Image {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgba;  // width · height · 4

  const uint8_t* pixel(int x, int y) const { return rgba.data() + 4 * (static_cast<size_t>(y) * width + x); }
};

}  // namespace animspace::render
