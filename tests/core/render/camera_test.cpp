// Tests of the camera arithmetic (core/render/camera.h) against closed-form pinhole geometry.
#include "core/render/camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <tuple>
#include <utility>

#include <gtest/gtest.h>

#include "tests/core/render/render_test_geometry.h"

namespace animspace::render {
namespace {

using testing::make_camera;

TEST(CameraTest, TargetProjectsToTheImageCentre) {
  const Camera camera = make_camera({1.5, -2, 7}, {0.2, 0.4, -1}, {0.1, 1, 0.3}, 0.9);
  const Projected p = project_to_pixel(camera, 320, 200, camera.target);
  EXPECT_NEAR(p.pixel.x(), 160, 1e-9);
  EXPECT_NEAR(p.pixel.y(), 100, 1e-9);
  EXPECT_NEAR(p.depth, (camera.target - camera.eye).norm(), 1e-9);
}

TEST(CameraTest, OffsetsFromTheViewAxisFollowTheFieldOfView) {
  // Eye on +z looking at the origin: a point at height h in the plane z = 0 is at angle atan(h/5)
  // and lands tan(angle) / tan(fov/2) half-heights above the centre.
  const double fov = 0.8;
  const Camera camera = make_camera({0, 0, 5}, {0, 0, 0}, {0, 1, 0}, fov);
  const int width = 400, height = 200;
  const double half_height_at_target = 5 * std::tan(fov / 2);
  const double half_width_at_target = 2 * half_height_at_target;

  Projected up = project_to_pixel(camera, width, height, {0, half_height_at_target / 2, 0});
  EXPECT_NEAR(up.pixel.x(), 200, 1e-9);
  EXPECT_NEAR(up.pixel.y(), 50, 1e-9);  // halfway to the top edge
  EXPECT_NEAR(up.depth, 5, 1e-12);

  Projected right = project_to_pixel(camera, width, height, {half_width_at_target, 0, 0});
  EXPECT_NEAR(right.pixel.x(), 400, 1e-9);  // NDC x = +1 is the right edge, pixel coordinate = width
  EXPECT_NEAR(right.pixel.y(), 100, 1e-9);

  Projected corner = project_to_pixel(camera, width, height, {-half_width_at_target, -half_height_at_target, 0});
  EXPECT_NEAR(corner.pixel.x(), 0, 1e-9);
  EXPECT_NEAR(corner.pixel.y(), 200, 1e-9);

  // Twice as far along the axis, the same offset subtends half as much.
  Projected far = project_to_pixel(camera, width, height, {0, half_height_at_target, -5});
  EXPECT_NEAR(far.pixel.y(), 50, 1e-9);
  EXPECT_NEAR(far.depth, 10, 1e-12);

  Projected behind = project_to_pixel(camera, width, height, {0, 0, 6});
  EXPECT_LT(behind.depth, 0);
}

TEST(CameraTest, MatricesMapTheFrustumToClipSpace) {
  const Camera camera = make_camera({2, 1, 4}, {0, 0.5, 0}, {0, 1, 0}, 0.7);
  const Eigen::Matrix4d view = view_matrix(camera);
  const Eigen::Vector4d eye = view * camera.eye.homogeneous();
  EXPECT_NEAR(eye.head<3>().norm(), 0, 1e-12);
  const double distance = (camera.target - camera.eye).norm();
  const Eigen::Vector4d target = view * camera.target.homogeneous();
  EXPECT_NEAR(target.x(), 0, 1e-12);
  EXPECT_NEAR(target.y(), 0, 1e-12);
  EXPECT_NEAR(target.z(), -distance, 1e-12);  // right-handed, looking down −z

  const double near_distance = 0.5, far_distance = 20, aspect = 1.6;
  const Eigen::Matrix4d projection = projection_matrix(camera, aspect, near_distance, far_distance);
  const auto ndc = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector4d clip = projection * Eigen::Vector4d(p.x(), p.y(), p.z(), 1);
    return Eigen::Vector3d(clip.head<3>() / clip.w());
  };
  EXPECT_NEAR(ndc({0, 0, -near_distance}).z(), -1, 1e-12);
  EXPECT_NEAR(ndc({0, 0, -far_distance}).z(), 1, 1e-12);
  // The top of the frustum at depth 3 is at y = 3·tan(fov/2), its right side at aspect times that.
  const double top = 3 * std::tan(0.35);
  EXPECT_NEAR(ndc({0, top, -3}).y(), 1, 1e-12);
  EXPECT_NEAR(ndc({aspect * top, 0, -3}).x(), 1, 1e-12);
}

TEST(CameraTest, HorizontalFieldOfView) {
  const Camera camera = make_camera({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, 0.8);
  EXPECT_NEAR(horizontal_fov(camera, 1), 0.8, 1e-12);
  EXPECT_NEAR(horizontal_fov(camera, 2), 2 * std::atan(2 * std::tan(0.4)), 1e-12);
  EXPECT_LT(horizontal_fov(camera, 0.5), 0.8);
}

TEST(CameraTest, FrameBoundingBoxKeepsEveryPointInsideTheImage) {
  std::mt19937 engine(7);
  std::uniform_real_distribution<float> coordinate(-3, 5);
  PointMatrix points(500, 3);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    points.row(i) << coordinate(engine), 0.2f * coordinate(engine), 2 * coordinate(engine);
  }
  for (const auto& [width, height] : {std::pair(256, 256), std::pair(400, 100), std::pair(90, 300)}) {
    SCOPED_TRACE(std::to_string(width) + " × " + std::to_string(height));
    Result<Camera> camera = frame_bounding_box(points, static_cast<double>(width) / height);
    ASSERT_TRUE(camera.ok()) << camera.error().message;
    // Looks at the bounding-box centre, level (+y up), along the horizontal axis the points spread
    // least on: x (uniform over 8 units) against z (over 16), so from +x.
    const Eigen::Vector3d centre =
        ((points.colwise().minCoeff() + points.colwise().maxCoeff()).cast<double>() / 2).transpose();
    EXPECT_TRUE(camera->target.isApprox(centre, 1e-9));
    EXPECT_NEAR((camera->eye - camera->target).normalized().x(), 1, 1e-3);
    EXPECT_NEAR((camera->eye - camera->target).normalized().y(), 0, 1e-12);
    EXPECT_TRUE(camera->up.isApprox(Eigen::Vector3d::UnitY()));
    EXPECT_TRUE(validate_camera(*camera, "camera").ok());
    const testing::Pinhole pinhole(camera->eye, camera->target, camera->up, camera->vertical_fov_rad, width,
                                   height);
    double margin = std::numeric_limits<double>::infinity();
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      const Eigen::Vector3d p = points.row(i).cast<double>().transpose();
      const Projected projected = project_to_pixel(*camera, width, height, p);
      EXPECT_GT(projected.depth, 0);
      EXPECT_TRUE(projected.pixel.isApprox(pinhole.project(p), 1e-9));
      margin = std::min({margin, projected.pixel.x(), width - projected.pixel.x(), projected.pixel.y(),
                         height - projected.pixel.y()});
    }
    EXPECT_GT(margin, 0);
  }
}

// Issue #55 item 13: the automatic camera shows a model at its widest. A figure facing +x (thin
// along x, arms spread along z) is seen from +x, one facing +z from +z; whatever the facing, the
// framed picture covers at least the bounding-box area of any other level view's, measured with
// the independent pinhole.
TEST(CameraTest, FrameBoundingBoxShowsTheModelAtItsWidest) {
  std::mt19937 engine(3);
  std::uniform_real_distribution<double> unit(-1, 1);
  const auto figure = [&](double facing_rad) {
    PointMatrix points(2000, 3);
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      const double depth = 0.15 * unit(engine), width = 0.8 * unit(engine), height = 1.8 * unit(engine);
      // facing_rad 0: thin along z; π/2: thin along x.
      points.row(i) << static_cast<float>(width * std::cos(facing_rad) + depth * std::sin(facing_rad)),
          static_cast<float>(height), static_cast<float>(-width * std::sin(facing_rad) + depth * std::cos(facing_rad));
    }
    return points;
  };
  const auto image_area = [](const PointMatrix& points, const Camera& camera) {
    const testing::Pinhole pinhole(camera.eye, camera.target, camera.up, camera.vertical_fov_rad, 200, 200);
    Eigen::Vector2d low = Eigen::Vector2d::Constant(1e300), high = -low;
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      const Eigen::Vector2d q = pinhole.project(points.row(i).cast<double>().transpose());
      low = low.cwiseMin(q);
      high = high.cwiseMax(q);
    }
    return (high - low).prod();
  };
  for (double facing : {0.0, std::numbers::pi / 2, 0.6}) {
    SCOPED_TRACE("facing " + std::to_string(facing));
    const PointMatrix points = figure(facing);
    Result<Camera> camera = frame_bounding_box(points, 1.0);
    ASSERT_TRUE(camera.ok()) << camera.error().message;
    const Eigen::Vector3d view = (camera->eye - camera->target).normalized();
    // The figure's thin axis, (sin φ, 0, cos φ), up to sign.
    EXPECT_GT(std::abs(view.dot(Eigen::Vector3d(std::sin(facing), 0, std::cos(facing)))), 0.99);
    const double ours = image_area(points, *camera);
    for (int k = 0; k < 12; ++k) {
      Camera other = *camera;
      const double a = k * std::numbers::pi / 12;
      other.eye = other.target + (camera->eye - camera->target).norm() * Eigen::Vector3d(std::sin(a), 0, std::cos(a));
      EXPECT_GE(ours, 0.98 * image_area(points, other)) << "view angle " << a;
    }
  }
}

// Framed into the left columns of the image (the heat legend takes the rest): every point lands
// in those columns and inside the image, checked with the independent pinhole of the tests, and
// the sphere's centre in the middle of the columns.
TEST(CameraTest, FrameInColumnsKeepsEveryPointLeftOfTheReservedColumns) {
  std::mt19937 engine(11);
  std::uniform_real_distribution<float> coordinate(-3, 5);
  PointMatrix points(500, 3);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    points.row(i) << coordinate(engine), 2 * coordinate(engine), 0.5f * coordinate(engine);
  }
  for (const auto& [width, height, columns] : {std::tuple(256, 256, 200), std::tuple(400, 100, 300),
                                               std::tuple(90, 300, 60), std::tuple(256, 256, 256)}) {
    SCOPED_TRACE(std::to_string(width) + " × " + std::to_string(height) + ", " + std::to_string(columns));
    Result<Camera> camera = frame_in_columns(points, width, height, columns);
    ASSERT_TRUE(camera.ok()) << camera.error().message;
    EXPECT_TRUE(validate_camera(*camera, "camera").ok());
    const testing::Pinhole pinhole(camera->eye, camera->target, camera->up, camera->vertical_fov_rad, width,
                                   height);
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      const Eigen::Vector2d pixel = pinhole.project(points.row(i).cast<double>().transpose());
      ASSERT_GT(pixel.x(), 0) << i;
      ASSERT_LT(pixel.x(), columns) << i;
      ASSERT_GT(pixel.y(), 0) << i;
      ASSERT_LT(pixel.y(), height) << i;
    }
    const geometry::BoundingSphere sphere = geometry::bounding_sphere(points);
    EXPECT_NEAR(pinhole.project(sphere.centre).x(), columns / 2.0, 1e-6 * width);
  }
  EXPECT_FALSE(frame_in_columns(points, 256, 256, 0).ok());
  EXPECT_FALSE(frame_in_columns(points, 256, 256, 257).ok());
}

TEST(CameraTest, FrameBoundingBoxRefusesNoPointsAndNonFinitePoints) {
  Result<Camera> empty = frame_bounding_box(PointMatrix(0, 3), 1);
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().code, ErrorCode::kInvalidArgument);
  PointMatrix points = PointMatrix::Zero(3, 3);
  points(1, 2) = std::numeric_limits<float>::quiet_NaN();
  Result<Camera> nan = frame_bounding_box(points, 1);
  ASSERT_FALSE(nan.ok());
  EXPECT_EQ(nan.error().code, ErrorCode::kInvalidArgument);
  // A single point still gets a usable camera.
  Result<Camera> single = frame_bounding_box(PointMatrix::Ones(1, 3), 1);
  ASSERT_TRUE(single.ok());
  EXPECT_TRUE(validate_camera(*single, "camera").ok());
}

TEST(CameraTest, ClipRangeEnclosesTheSphere) {
  const Camera camera = make_camera({0, 0, 10}, {0, 0, 0}, {0, 1, 0}, 0.8);
  const ClipRange range = clip_range(camera, geometry::BoundingSphere{Eigen::Vector3d(0, 0, 1), 2});
  EXPECT_GT(range.near_distance, 0);
  EXPECT_LT(range.near_distance, 10 - 1 - 2);
  EXPECT_GT(range.far_distance, 10 - 1 + 2);
  // Eye inside the sphere: a small positive near plane, not zero or negative.
  const ClipRange inside = clip_range(camera, geometry::BoundingSphere{Eigen::Vector3d(0, 0, 9), 3});
  EXPECT_GT(inside.near_distance, 0);
  EXPECT_GT(inside.far_distance, 1 + 3);
}

TEST(CameraTest, ValidateCameraNamesTheField) {
  const Camera good = make_camera({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, 0.8);
  EXPECT_TRUE(validate_camera(good, "camera").ok());

  const auto message = [](const Camera& camera) {
    const Status status = validate_camera(camera, "camera");
    EXPECT_FALSE(status.ok());
    if (status.ok()) return std::string();
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
    return status.error().message;
  };
  Camera camera = good;
  camera.up = Eigen::Vector3d(0, 0, -2);
  EXPECT_EQ(message(camera), "camera.up: parallel to the view direction (target − eye)");
  camera = good;
  camera.vertical_fov_rad = 3.5;
  EXPECT_EQ(message(camera), "camera.vertical_fov_rad: expected in (0, π), got 3.5");
  camera.vertical_fov_rad = 0;
  EXPECT_EQ(message(camera).rfind("camera.vertical_fov_rad:", 0), 0u);
  camera.vertical_fov_rad = std::numbers::pi;
  EXPECT_EQ(message(camera).rfind("camera.vertical_fov_rad:", 0), 0u);
  camera = good;
  camera.target = camera.eye;
  EXPECT_EQ(message(camera).rfind("camera.target:", 0), 0u);
  camera = good;
  camera.eye.x() = std::numeric_limits<double>::infinity();
  EXPECT_EQ(message(camera).rfind("camera.eye:", 0), 0u);
  camera = good;
  camera.up = Eigen::Vector3d::Zero();
  EXPECT_EQ(message(camera).rfind("camera.up:", 0), 0u);
  camera = good;
  camera.target.y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(message(camera).rfind("camera.target:", 0), 0u);
  // The prefix is the caller's.
  const Status nested = validate_camera(camera, "request.camera");
  ASSERT_FALSE(nested.ok());
  EXPECT_EQ(nested.error().message.rfind("request.camera.target:", 0), 0u);
}

}  // namespace
}  // namespace animspace::render
