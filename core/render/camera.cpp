#include "core/render/camera.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "core/common/format.h"

namespace animspace::render {

namespace {

// Camera basis: s right, u up, f forward (the camera looks along f, i.e. down its own −z).
struct Basis {
  Eigen::Vector3d s, u, f;
};

Basis basis(const Camera& camera) {
  Basis b;
  b.f = (camera.target - camera.eye).normalized();
  b.s = b.f.cross(camera.up).normalized();
  b.u = b.s.cross(b.f);
  return b;
}

// Margin around the bounding sphere when auto-framing, so that silhouettes do not touch the border.
constexpr double kFramingMargin = 1.05;
// Up to this sine of the angle between up and the view direction, they count as parallel: the
// basis would be dominated by rounding.
constexpr double kParallelSine = 1e-6;

// The level view direction (unit, in the xz plane; the camera sits at centre + distance · d) that
// shows `points` at their widest: the horizontal axis along which they spread least. Seen along
// it, the picture spans the vertical extent times the largest horizontal one, the most a level
// camera can show (issue #55 item 13: a dancer facing +x was drawn side-on from +z). Of its two
// signs, the one toward +z (glTF's front) when the axis is nearer z than x, else toward +x; a
// spread with no preferred axis (a turntable-symmetric model) keeps +z.
Eigen::Vector3d widest_level_view(const PointMatrix& points, const Eigen::Vector3d& centre) {
  Eigen::Matrix2d spread = Eigen::Matrix2d::Zero();  // second moments of (x, z) about the centre
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector2d q(points(i, 0) - centre.x(), points(i, 2) - centre.z());
    spread += q * q.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(spread);
  const Eigen::Vector2d values = eigen.eigenvalues();  // ascending
  if (!(values(1) > 0) || values(1) - values(0) <= 1e-6 * values(1)) return Eigen::Vector3d::UnitZ();
  Eigen::Vector3d d(eigen.eigenvectors()(0, 0), 0.0, eigen.eigenvectors()(1, 0));
  d.normalize();
  if ((std::abs(d.z()) >= std::abs(d.x()) ? d.z() : d.x()) < 0) d = -d;
  return d;
}

std::string vector_text(const Eigen::Vector3d& v) {
  return "(" + format_number(v.x()) + ", " + format_number(v.y()) + ", " + format_number(v.z()) + ")";
}

}  // namespace

Eigen::Matrix4d view_matrix(const Camera& camera) {
  const Basis b = basis(camera);
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();
  view.block<1, 3>(0, 0) = b.s.transpose();
  view.block<1, 3>(1, 0) = b.u.transpose();
  view.block<1, 3>(2, 0) = -b.f.transpose();
  view(0, 3) = -b.s.dot(camera.eye);
  view(1, 3) = -b.u.dot(camera.eye);
  view(2, 3) = b.f.dot(camera.eye);
  return view;
}

Eigen::Matrix4d projection_matrix(const Camera& camera, double aspect, double near_distance, double far_distance) {
  const double focal = 1.0 / std::tan(camera.vertical_fov_rad / 2);
  Eigen::Matrix4d projection = Eigen::Matrix4d::Zero();
  projection(0, 0) = focal / aspect;
  projection(1, 1) = focal;
  projection(2, 2) = (far_distance + near_distance) / (near_distance - far_distance);
  projection(2, 3) = 2 * far_distance * near_distance / (near_distance - far_distance);
  projection(3, 2) = -1;
  return projection;
}

Projected project_to_pixel(const Camera& camera, int width, int height, const Eigen::Vector3d& point) {
  const Basis b = basis(camera);
  const Eigen::Vector3d d = point - camera.eye;
  const double focal = 1.0 / std::tan(camera.vertical_fov_rad / 2);
  const double aspect = static_cast<double>(width) / height;
  Projected projected;
  projected.depth = d.dot(b.f);
  // Normalised device coordinates, then NDC −1 → pixel coordinate 0 and +1 → width (height, with
  // y flipped because image rows run top to bottom).
  const double ndc_x = focal / aspect * d.dot(b.s) / projected.depth;
  const double ndc_y = focal * d.dot(b.u) / projected.depth;
  projected.pixel = Eigen::Vector2d((ndc_x + 1) / 2 * width, (1 - ndc_y) / 2 * height);
  return projected;
}

double horizontal_fov(const Camera& camera, double aspect) {
  return 2 * std::atan(aspect * std::tan(camera.vertical_fov_rad / 2));
}

ClipRange clip_range(const Camera& camera, const geometry::BoundingSphere& sphere) {
  const Eigen::Vector3d to_centre = sphere.centre - camera.eye;
  const double depth = to_centre.dot((camera.target - camera.eye).normalized());
  double scale = std::max(sphere.radius, to_centre.norm());
  if (scale == 0) scale = 1;
  ClipRange range;
  // The sphere spans depths [depth − r, depth + r]; 10 % slack either side. An eye inside (or
  // just in front of) the sphere gets a near plane at 0.1 % of its size rather than 0, which
  // would leave no depth precision.
  range.near_distance = 0.9 * std::max(depth - sphere.radius, 1e-3 * scale);
  range.far_distance = std::max(1.1 * (depth + sphere.radius), 2 * range.near_distance);
  return range;
}

Result<Camera> frame_bounding_box(const PointMatrix& points, double aspect) {
  if (points.rows() == 0) return make_error(ErrorCode::kInvalidArgument, "points: no points to frame");
  if (!points.allFinite()) return make_error(ErrorCode::kInvalidArgument, "points: not all finite");
  if (!std::isfinite(aspect) || aspect <= 0) {
    return make_error(ErrorCode::kInvalidArgument, "aspect: expected > 0, got " + format_number(aspect));
  }
  const geometry::BoundingSphere sphere = geometry::bounding_sphere(points);
  // A single point (or all points equal) has no size: frame a unit sphere around it.
  const double radius = sphere.radius > 0 ? sphere.radius : 1.0;
  Camera camera;
  camera.target = sphere.centre;
  camera.up = Eigen::Vector3d::UnitY();
  camera.vertical_fov_rad = 0.8;
  // The sphere fits a cone of half-angle fov/2 when distance · sin(fov/2) ≥ radius.
  const double fov = std::min(camera.vertical_fov_rad, horizontal_fov(camera, aspect));
  camera.eye = sphere.centre + widest_level_view(points, sphere.centre) * (radius * kFramingMargin / std::sin(fov / 2));
  return camera;
}

Result<Camera> frame_in_columns(const PointMatrix& points, int width, int height, int columns) {
  if (width <= 0 || height <= 0 || columns <= 0 || columns > width) {
    return make_error(ErrorCode::kInvalidArgument, "columns: expected 1.." + std::to_string(std::max(width, 0)) +
                                                       " of a " + std::to_string(width) + " × " +
                                                       std::to_string(height) + " image, got " +
                                                       std::to_string(columns));
  }
  auto camera = frame_bounding_box(points, static_cast<double>(columns) / height);
  if (!camera) return camera.error();
  // A point at lateral offset X and depth d lands X · f / d pixels right of the image's centre,
  // f = (height / 2) / tan(fov / 2): moving the camera right by s = Δ · d / f puts the sphere's
  // centre Δ pixels left of it, in the middle of the columns.
  const double shift_px = 0.5 * (width - columns);
  const double depth = (camera->eye - camera->target).norm();
  const double focal_px = 0.5 * height / std::tan(camera->vertical_fov_rad / 2);
  const Eigen::Vector3d right = basis(*camera).s;
  camera->eye += shift_px * depth / focal_px * right;
  camera->target += shift_px * depth / focal_px * right;
  return camera;
}

Status validate_camera(const Camera& camera, const std::string& field) {
  const auto invalid = [&](const std::string& member, const std::string& what) {
    return Status(make_error(ErrorCode::kInvalidArgument, field + "." + member + ": " + what));
  };
  if (!camera.eye.allFinite()) return invalid("eye", "not finite " + vector_text(camera.eye));
  if (!camera.target.allFinite()) return invalid("target", "not finite " + vector_text(camera.target));
  if (!camera.up.allFinite()) return invalid("up", "not finite " + vector_text(camera.up));
  const Eigen::Vector3d view = camera.target - camera.eye;
  if (!view.allFinite()) return invalid("target", "too far from " + field + ".eye (target − eye overflows)");
  if (view.isZero(0)) return invalid("target", "equals " + field + ".eye, so there is no view direction");
  if (camera.up.isZero(0)) return invalid("up", "zero vector");
  // stableNormalized: coordinates like 1e200 would overflow a plain norm.
  if (view.stableNormalized().cross(camera.up.stableNormalized()).norm() <= kParallelSine) {
    return invalid("up", "parallel to the view direction (target − eye)");
  }
  const double fov = camera.vertical_fov_rad;
  if (!(fov > 0 && fov < std::numbers::pi)) {
    return invalid("vertical_fov_rad", "expected in (0, π), got " + format_number(fov));
  }
  return Status::Ok();
}

}  // namespace animspace::render
