// A thumbnail request's view, in process: what it writes into the scene, and each refusal
// naming its field with the expected and the actual value (table-driven).
#include "server/thumbnail_view.h"

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include <gtest/gtest.h>

namespace animspace::server {
namespace {

using Request = v1::RenderThumbnailRequest;

Request valid_request() {
  Request request;
  request.set_width_px(64);
  request.set_height_px(48);
  return request;
}

TEST(ThumbnailView, WritesTheRequestIntoTheScene) {
  ServerOptions options;
  Request request = valid_request();
  render::Scene scene;
  ASSERT_TRUE(read_thumbnail_view(request, options, scene).ok());
  EXPECT_EQ(scene.width, 64);
  EXPECT_EQ(scene.height, 48);
  EXPECT_EQ(scene.samples, 4);  // 0 = 4
  EXPECT_EQ(scene.shading, render::Shading::kBlinnPhong);
  EXPECT_FALSE(scene.camera);
  EXPECT_EQ(scene.background, render::Scene{}.background);

  request.set_samples(8);
  request.set_shading(Request::SHADING_LAMBERT);
  for (float v : {0.0f, 0.25f, 0.5f, 1.0f}) request.add_background_rgba(v);
  v1::Camera* camera = request.mutable_camera();
  for (float v : {1.0f, 2.0f, 5.0f}) camera->add_eye(v);
  for (float v : {0.0f, 0.5f, 0.0f}) camera->add_target(v);
  for (float v : {0.0f, 1.0f, 0.0f}) camera->add_up(v);
  camera->set_vertical_fov_rad(0.7f);
  ASSERT_TRUE(read_thumbnail_view(request, options, scene).ok());
  EXPECT_EQ(scene.samples, 8);
  EXPECT_EQ(scene.shading, render::Shading::kLambert);
  EXPECT_EQ(scene.background, Eigen::Vector4f(0, 0.25f, 0.5f, 1));
  ASSERT_TRUE(scene.camera);
  EXPECT_EQ(scene.camera->eye, Eigen::Vector3d(1, 2, 5));
  EXPECT_EQ(scene.camera->target, Eigen::Vector3d(0, 0.5, 0));
  EXPECT_EQ(scene.camera->up, Eigen::Vector3d(0, 1, 0));
  EXPECT_EQ(scene.camera->vertical_fov_rad, 0.7f);
}

TEST(ThumbnailView, ToleranceIsTolerancePxOrItsDeprecatedName) {
  Request request = valid_request();
  EXPECT_EQ(thumbnail_tolerance_px(request), 0);
  request.set_pixel_tolerance(1.5f);
  EXPECT_EQ(thumbnail_tolerance_px(request), 1.5f);
  request.set_tolerance_px(1.5f);  // both, agreeing
  EXPECT_EQ(thumbnail_tolerance_px(request), 1.5f);
  render::Scene scene;
  EXPECT_TRUE(read_thumbnail_view(request, ServerOptions{}, scene).ok());
  request.set_pixel_tolerance(0);
  EXPECT_EQ(thumbnail_tolerance_px(request), 1.5f);
}

TEST(ThumbnailView, RefusalsNameTheField) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  struct Case {
    std::function<void(Request&)> edit;
    std::string message;
  };
  const Case cases[] = {
      {[](Request& r) { r.set_width_px(0); }, "width_px: expected 1..100 pixels (--max-thumbnail-px), got 0"},
      {[](Request& r) { r.set_height_px(101); }, "height_px: expected 1..100 pixels (--max-thumbnail-px), got 101"},
      {[](Request& r) { r.set_samples(3); }, "samples: expected 1, 2, 4 or 8 (0 = 4), got 3"},
      {[](Request& r) { r.add_background_rgba(0); }, "background_rgba: expected 4 values (RGBA), got 1"},
      {[](Request& r) {
         for (float v : {0.0f, 0.0f, 1.5f, 1.0f}) r.add_background_rgba(v);
       },
       "background_rgba[2]: expected a value in [0, 1], got 1.500000"},
      {[](Request& r) { r.set_shading(static_cast<Request::Shading>(42)); }, "shading: unknown value 42"},
      {[](Request& r) { r.set_tolerance_px(-1); },
       "tolerance_px: expected a finite value ≥ 0 (0 = full detail), got -1.000000"},
      {[nan](Request& r) { r.set_pixel_tolerance(nan); },
       "pixel_tolerance: expected a finite value ≥ 0 (0 = full detail), got nan"},
      {[](Request& r) {
         r.set_tolerance_px(2);
         r.set_pixel_tolerance(3);
       },
       "tolerance_px: 2 disagrees with pixel_tolerance (its deprecated name), 3; send tolerance_px only"},
      {[](Request& r) { r.mutable_camera()->add_eye(1); }, "camera.eye: expected 3 values, got 1"},
  };
  ServerOptions options;
  options.max_thumbnail_px = 100;
  for (const Case& c : cases) {
    Request request = valid_request();
    c.edit(request);
    render::Scene scene;
    const grpc::Status status = read_thumbnail_view(request, options, scene);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.message;
    EXPECT_EQ(status.error_message(), c.message);
  }
}

TEST(ThumbnailView, ACameraTheCoreRefusesCrossesAsInvalidArgument) {
  Request request = valid_request();
  v1::Camera* camera = request.mutable_camera();
  for (int i = 0; i < 3; ++i) {
    camera->add_eye(1);
    camera->add_target(1);  // target = eye
    camera->add_up(i == 1 ? 1.0f : 0.0f);
  }
  camera->set_vertical_fov_rad(0.8f);
  render::Scene scene;
  const grpc::Status status = read_thumbnail_view(request, ServerOptions{}, scene);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(status.error_message().rfind("camera.", 0), 0u) << status.error_message();
  EXPECT_FALSE(scene.camera);
}

}  // namespace
}  // namespace animspace::server
