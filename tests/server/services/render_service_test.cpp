// RenderService.RenderThumbnail's logic in process, drawing with the fake renderer
// (tests/server/support): what the request asks for reaches the renderer unchanged, what the
// renderer draws comes back as the PNG, and a bad field is refused — naming it — before the
// renderer is asked for anything. Real pictures are tests/integration/render_service_test.cpp's.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/render.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/model/model_info.h"
#include "core/render/camera.h"
#include "core/render/heat_legend.h"
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

v1::PointArray point_array(const float* values, uint32_t count) {
  v1::PointArray a;
  a.set_point_count(count);
  a.set_channel_count(3);
  a.set_data(values, sizeof(float) * 3 * count);
  return a;
}

// The heat map of a soft-cache estimate: what red means (the model's error tolerance unless the
// request names a scale), the largest error, and the legend that says so on the image.
TEST_F(RenderServiceInProcessTest, TheHeatMapIsScaledToTheModelsToleranceAndItsLegendIsDrawn) {
  const std::string pmsc(demo::kDemoPmscModelName);
  auto stored = container::read_file(repository() / pmsc / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  // The model's error tolerance as the trainer wrote it (model units).
  const double tolerance = std::stod(stored->metadata_value("pmsc.options.error_tolerance"));
  ASSERT_GT(tolerance, 0);
  auto frames_file = container::read_file(repository() / kArm / "1" / "model.anim");
  ASSERT_TRUE(frames_file.ok());
  auto frames = frames_file->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());
  const int f = 3;
  const Eigen::RowVectorXf full = frames->row(f);
  const auto n = static_cast<uint32_t>(full.size() / 3);

  auto poses = v1::PoseService::NewStub(server_->channel());
  v1::DescribeKeyPointsResponse keys;
  {
    grpc::ClientContext context;
    v1::DescribeKeyPointsRequest describe;
    describe.mutable_model()->set_name(pmsc);
    ASSERT_TRUE(poses->DescribeKeyPoints(&context, describe, &keys).ok());
  }
  std::vector<float> key_values;
  for (uint32_t k : keys.key_point_indices()) {
    for (int c = 0; c < 3; ++c) key_values.push_back(full(3 * k + c));
  }
  const auto K = static_cast<uint32_t>(keys.key_point_indices_size());
  // The estimate the soft cache returns for these key points, and its largest distance from the frame.
  double largest = 0;
  {
    grpc::ClientContext context;
    v1::EvaluateKeyPointsRequest evaluate;
    evaluate.mutable_model()->set_name(pmsc);
    *evaluate.add_poses()->mutable_key_values() = point_array(key_values.data(), K);
    v1::EvaluateKeyPointsResponse evaluated;
    ASSERT_TRUE(poses->EvaluateKeyPoints(&context, evaluate, &evaluated).ok());
    const std::string& data = evaluated.results(0).points().data();
    ASSERT_EQ(data.size(), sizeof(float) * full.size());
    for (uint32_t p = 0; p < n; ++p) {
      double squared = 0;
      for (int c = 0; c < 3; ++c) {
        float value = 0;
        std::memcpy(&value, data.data() + sizeof(float) * (3 * p + c), sizeof value);
        squared += (double(value) - full(3 * p + c)) * (double(value) - full(3 * p + c));
      }
      largest = std::max(largest, std::sqrt(squared));
    }
  }

  Request r = request(pmsc, 256, 256);
  *r.mutable_key_points()->mutable_key_values() = point_array(key_values.data(), K);
  *r.mutable_full_values() = point_array(full.data(), n);
  r.set_show_heat_legend(true);
  v1::RenderThumbnailResponse response;
  const grpc::Status status = render(r, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_NEAR(response.heat_max_error(), largest, 1e-6 * largest + 1e-9);
  EXPECT_DOUBLE_EQ(response.heat_scale_max(), tolerance) << "red is the model's tolerance";
  EXPECT_TRUE(response.heat_legend_drawn());
  const auto scenes = server_->renders().scenes();
  ASSERT_EQ(scenes.size(), 1u);
  EXPECT_FLOAT_EQ(scenes[0].heat_max, static_cast<float>(tolerance));
  ASSERT_EQ(scenes[0].heat.size(), static_cast<Eigen::Index>(n));
  EXPECT_NEAR(scenes[0].heat.maxCoeff(), largest, 1e-6 * largest + 1e-9);

  // The legend over the fake renderer's picture: red at the top of its bar, blue at the bottom,
  // the renderer's own pixels elsewhere.
  auto image = render::decode_png(response.png(), "thumbnail");
  ASSERT_TRUE(image.ok()) << image.error().message;
  const render::HeatLegendLayout legend = render::heat_legend_layout(256, 256, response.heat_scale_max());
  ASSERT_TRUE(legend.fits);
  EXPECT_EQ(legend.labels[0], render::legend_label(response.heat_scale_max()));
  const int x = (legend.bar_x0 + legend.bar_x1) / 2;
  const uint8_t* top = image->pixel(x, legend.bar_y0);
  const uint8_t* bottom = image->pixel(x, legend.bar_y1 - 1);
  EXPECT_EQ(std::vector<uint8_t>(top, top + 3), (std::vector<uint8_t>{255, 0, 0}));
  EXPECT_EQ(std::vector<uint8_t>(bottom, bottom + 3), (std::vector<uint8_t>{0, 0, 255}));
  const auto fake = FakeRenderer::fake_pixel(3, 3);
  const uint8_t* outside = image->pixel(3, 3);
  EXPECT_EQ(std::vector<uint8_t>(outside, outside + 4), std::vector<uint8_t>(fake.begin(), fake.end()));

  // The legend covers none of the model (issue #39): with no camera given, every point projects
  // into the columns left of the legend's panel, and inside the image.
  ASSERT_TRUE(scenes[0].camera.has_value()) << "the model is framed beside the legend";
  for (Eigen::Index i = 0; i < scenes[0].points.rows(); ++i) {
    const Eigen::Vector3d point = scenes[0].points.row(i).transpose().cast<double>();
    const Eigen::Vector2d pixel = render::project_to_pixel(*scenes[0].camera, 256, 256, point).pixel;
    ASSERT_GE(pixel.x(), 0.0) << "point " << i;
    ASSERT_LT(pixel.x(), legend.panel_x0) << "point " << i << " lies under the legend";
    ASSERT_GE(pixel.y(), 0.0) << "point " << i;
    ASSERT_LT(pixel.y(), 256.0) << "point " << i;
  }

  // A scale the caller names is the one drawn; no legend unless asked.
  r.set_heat_max(0.5f);
  r.set_show_heat_legend(false);
  ASSERT_TRUE(render(r, &response).ok());
  EXPECT_DOUBLE_EQ(response.heat_scale_max(), 0.5);
  EXPECT_FALSE(response.heat_legend_drawn());
  EXPECT_FLOAT_EQ(server_->renders().scenes().back().heat_max, 0.5f);

  // The heat fields without full_values, or a scale that is no scale, are refused, naming them.
  for (const auto& [spoil, field] : std::vector<std::pair<std::function<void(Request&)>, std::string>>{
           {[](Request& q) { q.clear_full_values(); }, "heat_max"},
           {[](Request& q) {
              q.clear_full_values();
              q.set_heat_max(0);
              q.set_show_heat_legend(true);
            },
            "show_heat_legend"},
           {[](Request& q) { q.set_heat_max(-1); }, "heat_max"},
           {[&full, n](Request& q) {
              Eigen::RowVectorXf huge = full;
              huge.head<3>().setConstant(3e38f);  // finite, but its distance from the estimate is not
              *q.mutable_full_values() = point_array(huge.data(), n);
            },
            "full_values: |full − estimate| overflows float32"}}) {
    Request bad = r;
    spoil(bad);
    const grpc::Status refused = render(bad);
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << field;
    EXPECT_NE(refused.error_message().find(field), std::string::npos) << refused.error_message();
  }
  EXPECT_EQ(server_->renders().scenes().size(), 2u) << "nothing refused reaches the renderer";
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
