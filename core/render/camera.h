// Camera arithmetic shared by the renderer, the LOD choice of a thumbnail and the tests: view and
// projection matrices (OpenGL conventions), projecting a point to a pixel, and auto-framing.
#pragma once

#include <Eigen/Core>

#include "core/common/result.h"
#include "core/common/types.h"
#include "core/geometry/bounding_sphere.h"
#include "core/render/scene.h"

namespace animspace::render {

// Right-handed look-at view matrix (the camera looks down −z).
Eigen::Matrix4d view_matrix(const Camera& camera);
// Perspective projection for `aspect` = width / height, near and far clip distances > 0.
Eigen::Matrix4d projection_matrix(const Camera& camera, double aspect, double near_distance, double far_distance);

// The pixel (x right, y down, pixel centres at half-integers, origin at the top-left corner of
// the image) that `point` projects to, and its distance along the view direction (> 0 in
// front of the camera).
struct Projected {
  Eigen::Vector2d pixel;
  double depth = 0;
};
Projected project_to_pixel(const Camera& camera, int width, int height, const Eigen::Vector3d& point);

// The horizontal field of view of `camera` on an image of `aspect` = width / height.
double horizontal_fov(const Camera& camera, double aspect);

// A camera that sees the whole of `points`: level (up +y), it looks at the centre of their bounding
// sphere (geometry::bounding_sphere) along the horizontal axis of least spread, so that the view
// shows the model at its widest (a dancer facing +x from +x, a horse from its side), from the +z
// side of that axis; far enough that the sphere fits the narrower field of view with a small margin.
// Errors: kInvalidArgument for no points or non-finite points.
Result<Camera> frame_bounding_box(const PointMatrix& points, double aspect);

// The same framing into the left `columns` pixel columns of a width × height image (0 < columns
// ≤ width), the rest left to something drawn over the picture (the heat legend): the sphere fits
// the fields of view of a columns × height image, and the camera is moved along its right axis
// so that the sphere's centre projects to the middle of those columns. Errors: as above, and
// kInvalidArgument for sizes out of range.
Result<Camera> frame_in_columns(const PointMatrix& points, int width, int height, int columns);

// Near and far clip distances for drawing `sphere` from `camera`: tight around the sphere so the
// 24-bit depth buffer keeps its precision, with a floor on `near` for an eye inside the sphere.
struct ClipRange {
  double near_distance = 0;
  double far_distance = 0;
};
ClipRange clip_range(const Camera& camera, const geometry::BoundingSphere& sphere);

// Checks a camera given by a caller: finite, eye ≠ target, up not parallel to the view direction,
// field of view in (0, π). Errors: kInvalidArgument naming `field` (e.g. "camera.up") and what
// was wrong.
Status validate_camera(const Camera& camera, const std::string& field);

}  // namespace animspace::render
