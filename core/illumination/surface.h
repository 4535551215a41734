// The surface the illumination lives on, and the classic Cornell box.
//
// Meyer & Anderson 2006 §8 / 2007 §3.2 compute indirect illumination at image-space points; we
// store it at surface sample points (the vertices of a tessellation) so the result can be drawn
// from any camera. Every planar face of the scene gets its own vertices: illumination is
// discontinuous across a crease, and each vertex has one normal and one albedo.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"

namespace animspace::illumination {

// A diffuse scene: triangles whose vertices are the illumination's sample points.
struct SurfaceMesh {
  PointMatrix vertices;  // N × 3, metres
  PointMatrix normals;   // N × 3, unit, pointing to the side that is lit (into the room)
  PointMatrix albedo;    // N × 3, diffuse reflectance ρ per RGB channel, in [0, 1)
  FaceMatrix faces;      // T × 3, counter-clockwise seen from the lit side
};

// Checks shapes (equal row counts, faces in range), finiteness, unit normals (|‖n‖ − 1| ≤ 1e-3)
// and albedo in [0, 1). Errors: kInvalidArgument naming `name`.<member>, the row and the value.
Status check_surface(const SurfaceMesh& surface, const std::string& name);

// A point light: radiant intensity I per RGB channel (W/sr), so that the irradiance at distance
// r, at angle θ from the normal, is I cos θ / r².
struct PointLight {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d intensity = Eigen::Vector3d::Ones();
};

// The Cornell box as measured by the Cornell Program of Computer Graphics ("Cornell Box Data",
// https://www.graphics.cornell.edu/online/box/data.html): the 556 × 549 × 559 mm room (floor,
// ceiling, back wall, red left wall, green right wall; open at the front where the camera
// stands), the short and the tall block, in metres, y up. The ceiling's area light is left out
// (the papers replace it with a point light). Reflectances are the usual RGB reductions of the
// measured spectra (white 0.73/0.71/0.68, red 0.63/0.065/0.05, green 0.14/0.45/0.091).
//
// Each face is cut into a grid of near-square cells whose side is chosen so that the whole
// scene has about `target_points` vertices (never fewer than 4 per face).
struct CornellBoxOptions {
  int target_points = 100000;
};
SurfaceMesh cornell_box(const CornellBoxOptions& options);

// The room's interior box (min, max corners) of cornell_box(): where lights may be placed.
struct Box {
  Eigen::Vector3d min;
  Eigen::Vector3d max;
};
Box cornell_room();

// The training lights of Meyer & Anderson 2007 §3.2: an nx × nz grid in a horizontal plane
// `drop` (fraction of the room's height) below the ceiling, inset by `inset` (fraction of the
// room's width and depth) from the walls. Positions are row-major in (z, x).
//
// Why 20% below the ceiling ("along the ceiling" in the papers): a point light at distance h from
// a surface lights a spot about h wide, and the indirect illumination inherits that feature; the
// subspace can only interpolate between training lights if the features are wider than the grid's
// spacing. At 5% (2.7 cm) the training frames' own key-point reconstruction was off by half the
// frame's largest radiance; 20% puts the plane midway between the ceiling and the tall block's
// top (11 cm from each), where the nearest surface is farthest (docs/BENCHMARKS.md).
//
// Why 18 × 18 (spacing 2.6 cm, about h/4) rather than the papers' 12 × 12 (4 cm, h/2.7): once the
// gather converged (issue #38), what the subspace missed on novel lights between the training
// lights was the features' motion between them, not noise. At the papers' 100k points the 18 × 18
// grid took the estimate's median relative RMS error against the full calculation from 1.35% to
// 0.76% (against a 4,096-ray reference: 1.43% → 1.04%), for 2.25× the training lights, which share
// the gather's rays (docs/BENCHMARKS.md, "Issue #38: a denser training grid").
struct LightGrid {
  int nx = 18;
  int nz = 18;
  double drop = 0.2;
  double inset = 0.1;
};
std::vector<Eigen::Vector3d> light_grid(const Box& room, const LightGrid& grid);

}  // namespace animspace::illumination
