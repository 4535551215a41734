// RenderService.RenderThumbnail's logic in process, drawing with the fake renderer
// (tests/server/support): what the request asks for reaches the renderer unchanged, what the
// renderer draws comes back as the PNG, and a bad field is refused — naming it — before the
// renderer is asked for anything. Real pictures are tests/integration/render_service_test.cpp's.
#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/model/model_info.h"
#include "core/render/png.h"
#include "server/implemented_rpcs.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::FakeRenderer;
using testing::InProcessServer;
using testing::TempDir;
using Request = v1::RenderThumbnailRequest;

const std::string kArm(demo::kDemoModelName);

class RenderServiceInProcessTest : public testing::SmallRepositoryTest {
 protected:
  void SetUp() override {
    server::ServerOptions options;
    options.miss_log_dir = work_.path();
    options.max_thumbnail_px = 512;
    server_ = std::make_unique<InProcessServer>(repository(), options);
    stub_ = v1::RenderService::NewStub(server_->channel());
  }

  static Request request(const std::string& model, uint32_t width, uint32_t height) {
    Request r;
    r.mutable_model()->set_name(model);
    r.set_width_px(width);
    r.set_height_px(height);
    return r;
  }

  grpc::Status render(const Request& r, v1::RenderThumbnailResponse* response = nullptr) {
    v1::RenderThumbnailResponse ignored;
    grpc::ClientContext context;
    return stub_->RenderThumbnail(&context, r, response != nullptr ? response : &ignored);
  }

  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::RenderService::Stub> stub_;
};

TEST_F(RenderServiceInProcessTest, TheRequestsViewReachesTheRendererAndItsImageComesBack) {
  Request r = request(kArm, 96, 64);
  r.set_samples(2);
  r.set_shading(Request::SHADING_LAMBERT);
  r.set_show_wireframe(true);
  for (float c : {0.25f, 0.5f, 0.75f, 1.0f}) r.add_background_rgba(c);
  for (float v : {1.0f, 2.0f, 9.0f}) r.mutable_camera()->add_eye(v);
  for (float v : {0.5f, 0.0f, -1.0f}) r.mutable_camera()->add_target(v);
  for (float v : {0.0f, 1.0f, 0.0f}) r.mutable_camera()->add_up(v);
  r.mutable_camera()->set_vertical_fov_rad(0.5f);
  v1::RenderThumbnailResponse response;
  const grpc::Status status = render(r, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();

  const auto scenes = server_->renders().scenes();
  ASSERT_EQ(scenes.size(), 1u);
  const render::Scene& scene = scenes[0];
  EXPECT_EQ(scene.width, 96);
  EXPECT_EQ(scene.height, 64);
  EXPECT_EQ(scene.samples, 2);
  EXPECT_EQ(scene.shading, render::Shading::kLambert);
  EXPECT_TRUE(scene.wireframe);
  EXPECT_EQ(scene.background, Eigen::Vector4f(0.25f, 0.5f, 0.75f, 1.0f));
  ASSERT_TRUE(scene.camera.has_value());
  EXPECT_EQ(scene.camera->eye, Eigen::Vector3d(1, 2, 9));
  EXPECT_EQ(scene.camera->target, Eigen::Vector3d(0.5, 0, -1));
  EXPECT_EQ(scene.camera->up, Eigen::Vector3d(0, 1, 0));
  EXPECT_DOUBLE_EQ(scene.camera->vertical_fov_rad, 0.5f);
  // The source is the rest pose: the stored one, with the stored faces.
  auto stored = container::read_file(repository() / kArm / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  auto rest = stored->points(container::sections::kRestPoints);
  auto faces = stored->faces(container::sections::kFaces);
  ASSERT_TRUE(rest.ok() && faces.ok());
  EXPECT_EQ(scene.points, *rest);
  EXPECT_EQ(scene.faces, *faces);

  EXPECT_EQ(response.width_px(), 96u);
  EXPECT_EQ(response.height_px(), 64u);
  EXPECT_EQ(response.model_version(), 1u);
  auto image = render::decode_png(response.png(), "thumbnail");
  ASSERT_TRUE(image.ok()) << image.error().message;
  ASSERT_EQ(image->width, 96);
  ASSERT_EQ(image->height, 64);
  for (const auto& [x, y] : {std::pair{0, 0}, {95, 0}, {40, 33}, {95, 63}}) {
    const auto expected = FakeRenderer::fake_pixel(x, y);
    const uint8_t* got = image->pixel(x, y);
    EXPECT_EQ(std::vector<uint8_t>(got, got + 4), std::vector<uint8_t>(expected.begin(), expected.end()))
        << "pixel (" << x << ", " << y << ")";
  }
}

TEST_F(RenderServiceInProcessTest, WithoutACameraTheRendererFramesTheMeshItself) {
  ASSERT_TRUE(render(request(kArm, 32, 32)).ok());
  const auto scenes = server_->renders().scenes();
  ASSERT_EQ(scenes.size(), 1u);
  EXPECT_FALSE(scenes[0].camera.has_value()) << "absent camera: the renderer frames the bounding box";
  EXPECT_EQ(scenes[0].samples, 4) << "samples 0 means 4";
}

TEST_F(RenderServiceInProcessTest, BadFieldsAreRefusedBeforeTheRendererIsCalled) {
  using Code = grpc::StatusCode;
  struct Case {
    std::string name;
    std::function<void(Request&)> spoil;
    Code code;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"zero width", [](Request& r) { r.set_width_px(0); }, Code::INVALID_ARGUMENT, "width_px: expected 1..512"},
      {"too high", [](Request& r) { r.set_height_px(513); }, Code::INVALID_ARGUMENT, "height_px: expected 1..512"},
      {"samples", [](Request& r) { r.set_samples(3); }, Code::INVALID_ARGUMENT, "samples: expected 1, 2, 4 or 8"},
      {"background", [](Request& r) { r.add_background_rgba(1); }, Code::INVALID_ARGUMENT,
       "background_rgba: expected 4 values"},
      {"camera eye", [](Request& r) { r.mutable_camera()->add_eye(1); }, Code::INVALID_ARGUMENT,
       "camera.eye: expected 3 values, got 1"},
      {"camera up along the view",
       [](Request& r) {
         for (float v : {0.0f, 0.0f, 5.0f}) r.mutable_camera()->add_eye(v);
         for (float v : {0.0f, 0.0f, 0.0f}) r.mutable_camera()->add_target(v);
         for (float v : {0.0f, 0.0f, 1.0f}) r.mutable_camera()->add_up(v);
         r.mutable_camera()->set_vertical_fov_rad(0.7f);
       },
       Code::INVALID_ARGUMENT, "camera.up"},
      {"tolerance", [](Request& r) { r.set_tolerance_px(-1); }, Code::INVALID_ARGUMENT, "tolerance_px: expected"},
      {"frame", [](Request& r) { r.set_sequence_frame(100000); }, Code::INVALID_ARGUMENT,
       "sequence_frame: expected 0.."},
      {"unknown model", [](Request& r) { r.mutable_model()->set_name("no-such-model"); }, Code::NOT_FOUND,
       "no-such-model"},
      {"path as name", [](Request& r) { r.mutable_model()->set_name("../arm"); }, Code::INVALID_ARGUMENT, "model.name"},
      {"key points on a mesh", [](Request& r) { r.set_show_key_points(true); }, Code::FAILED_PRECONDITION,
       "show_key_points"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    Request r = request(kArm, 64, 64);
    c.spoil(r);
    const grpc::Status status = render(r);
    EXPECT_EQ(status.error_code(), c.code) << status.error_message();
    EXPECT_NE(status.error_message().find(c.message), std::string::npos) << status.error_message();
  }
  EXPECT_TRUE(server_->renders().scenes().empty());
}

TEST_F(RenderServiceInProcessTest, ServerInfoNamesTheRendererAndListsThumbnails) {
  auto models = v1::ModelService::NewStub(server_->channel());
  grpc::ClientContext context;
  v1::GetServerInfoResponse info;
  ASSERT_TRUE(models->GetServerInfo(&context, v1::GetServerInfoRequest(), &info).ok());
  EXPECT_EQ(info.renderer(), FakeRenderer::kDescription);
  const auto& rpcs = info.implemented_rpcs();
  EXPECT_NE(std::find(rpcs.begin(), rpcs.end(), std::string(server::kRenderThumbnailRpc)), rpcs.end());
}

}  // namespace
}  // namespace animspace
