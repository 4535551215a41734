// RenderService.RenderThumbnail against the real animspaced, drawing on its own render thread
// through EGL (Mesa surfaceless on machines without a GPU). The pictures are checked through
// what the test computes itself: the requested size and background, the projected positions of
// the key points (render::project_to_pixel of the points EvaluateKeyPoints returns), the level
// eq. 7.2 allows for the thumbnail's camera, and exact statuses for bad requests.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "core/lod/selection.h"
#include "core/container/sections.h"
#include "core/common/atomic_file.h"
#include "core/render/camera.h"
#include "core/render/heat_legend.h"
#include "core/render/png.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/support/cli_run.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;

// A flat background no shaded pixel of the arm can have.
constexpr float kBackground[4] = {0.0f, 0.0f, 1.0f, 1.0f};

class RenderServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repo_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(repo_->path()).ok());
  }
  static void TearDownTestSuite() {
    delete repo_;
    repo_ = nullptr;
  }

  std::unique_ptr<DaemonProcess> start(std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--model-repository", repo_->path().string(), "--log-level", "info",
                                  "--miss-log-dir", work_.path().string()};
    // Surfaceless explicitly, so that a machine without EGL fails here loudly instead of quietly
    // serving without thumbnails.
    if (std::find(extra.begin(), extra.end(), "--renderer") == extra.end()) {
      args.insert(args.end(), {"--renderer", "surfaceless"});
    }
    args.insert(args.end(), extra.begin(), extra.end());
    auto daemon = std::make_unique<DaemonProcess>(args, work_.path());
    Client client(daemon->address());
    EXPECT_TRUE(testing::wait_until_serving(client)) << "never SERVING\n" << daemon->log();
    return daemon;
  }

  static v1::RenderThumbnailRequest request(const std::string& model, uint32_t width, uint32_t height) {
    v1::RenderThumbnailRequest r;
    r.mutable_model()->set_name(model);
    r.set_width_px(width);
    r.set_height_px(height);
    for (float c : kBackground) r.add_background_rgba(c);
    return r;
  }

  static render::Image decode(const Thumbnail& thumbnail) {
    auto image = render::decode_png(thumbnail.png, "thumbnail");
    EXPECT_TRUE(image.ok()) << image.error().message;
    return image.ok() ? std::move(*image) : render::Image{};
  }

  static bool is_background(const render::Image& image, int x, int y) {
    const uint8_t* p = image.pixel(x, y);
    return p[0] == 0 && p[1] == 0 && p[2] == 255;
  }

  static inline TempDir* repo_ = nullptr;
  TempDir work_;
};

std::string status_text(const RpcError& e) { return std::string(status_code_name(e.code())) + ": " + e.server_message(); }

// Expects `call` to fail with `code` and a message containing `part`.
void expect_refused(const std::function<void()>& call, grpc::StatusCode code, const std::string& part) {
  try {
    call();
    ADD_FAILURE() << "expected " << status_code_name(code) << " containing '" << part << "', got OK";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), code) << status_text(e);
    EXPECT_NE(e.server_message().find(part), std::string::npos) << status_text(e);
  }
}

// The heat legend's bar on a drawn image: red at the top of the scale, blue at 0.
void expect_legend_bar(const render::Image& image, double scale_max) {
  const render::HeatLegendLayout legend = render::heat_legend_layout(image.width, image.height, scale_max);
  ASSERT_TRUE(legend.fits);
  const int x = (legend.bar_x0 + legend.bar_x1) / 2;
  const uint8_t* top = image.pixel(x, legend.bar_y0);
  const uint8_t* bottom = image.pixel(x, legend.bar_y1 - 1);
  EXPECT_EQ(std::vector<uint8_t>(top, top + 3), (std::vector<uint8_t>{255, 0, 0})) << "red at the top of the scale";
  EXPECT_EQ(std::vector<uint8_t>(bottom, bottom + 3), (std::vector<uint8_t>{0, 0, 255})) << "blue at 0";
}

TEST_F(RenderServiceTest, DrawsTheRestPoseAtTheRequestedSizeOnTheRequestedBackground) {
  auto daemon = start();
  Client client(daemon->address());
  EXPECT_NE(client.server_info().renderer().find("EGL surfaceless"), std::string::npos)
      << client.server_info().renderer();

  for (const char* model : {"arm", "arm-animspace", "arm-pmsc"}) {
    SCOPED_TRACE(model);
    const auto response = client.render_thumbnail(request(model, 160, 96));
    EXPECT_EQ(response.width_px, 160u);
    EXPECT_EQ(response.height_px, 96u);
    EXPECT_GT(response.model_version, 0u);
    EXPECT_GT(response.render_ms, 0.0);
    const render::Image image = decode(response);
    ASSERT_EQ(image.width, 160);
    ASSERT_EQ(image.height, 96);
    // Auto-framed: the corners are background, the centre is the arm.
    EXPECT_TRUE(is_background(image, 0, 0));
    EXPECT_TRUE(is_background(image, 159, 95));
    EXPECT_FALSE(is_background(image, 80, 48));
  }
}

TEST_F(RenderServiceTest, TheWireframeOverlayDrawsEdgesInItsColour) {
  auto daemon = start();
  Client client(daemon->address());
  // The default wireframe colour is near black, which neither the lit arm nor the blue background
  // has: count such pixels with and without the overlay.
  const auto dark_pixels = [&](bool wireframe) {
    auto r = request("arm-animspace", 256, 256);
    r.set_show_wireframe(wireframe);
    const render::Image image = decode(client.render_thumbnail(r));
    int dark = 0;
    for (int y = 0; y < image.height; ++y) {
      for (int x = 0; x < image.width; ++x) {
        const uint8_t* p = image.pixel(x, y);
        dark += p[0] < 30 && p[1] < 30 && p[2] < 30;
      }
    }
    return dark;
  };
  const int without = dark_pixels(false);
  const int with = dark_pixels(true);
  EXPECT_GT(with, without + 200) << "without " << without << ", with " << with;
}

TEST_F(RenderServiceTest, KeyPointDotsLandWhereTheEstimateProjects) {
  auto daemon = start();
  Client client(daemon->address());
  auto stored = container::read_file(repo_->path() / "arm" / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  auto frames = stored->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());

  const std::string model = std::string(demo::kDemoPmscModelName);
  const auto keys = client.describe_key_points(model);
  const int frame = 7;  // an odd frame: one the cache was not trained on
  const std::vector<float> key_values =
      keys.gather(std::span<const float>(frames->row(frame).data(), static_cast<size_t>(frames->cols())));
  const auto key_array =
      make_point_array(key_values.data(), static_cast<uint32_t>(keys.indices.size()), keys.channel_count);

  // What the soft cache returns for these key points, evaluated separately.
  const PoseResult evaluated = client.evaluate_key_points(model, {key_values, keys.channel_count});
  const PointMatrix estimate = Eigen::Map<const PointMatrix>(evaluated.points.values.data(), evaluated.points.point_count, 3);

  // A known camera looking at the arm from the front.
  render::Camera camera;
  const Eigen::Vector3f lo = estimate.colwise().minCoeff();
  const Eigen::Vector3f hi = estimate.colwise().maxCoeff();
  camera.target = ((lo + hi) / 2).cast<double>();
  camera.eye = camera.target + Eigen::Vector3d(0, 0, 3.0 * (hi - lo).norm());
  camera.vertical_fov_rad = 0.6;

  auto r = request(model, 320, 240);
  *r.mutable_key_points()->mutable_key_values() = key_array;
  r.set_show_key_points(true);
  r.set_samples(1);
  for (double v : {camera.eye.x(), camera.eye.y(), camera.eye.z()}) r.mutable_camera()->add_eye(static_cast<float>(v));
  for (double v : {camera.target.x(), camera.target.y(), camera.target.z()}) {
    r.mutable_camera()->add_target(static_cast<float>(v));
  }
  for (float v : {0.0f, 1.0f, 0.0f}) r.mutable_camera()->add_up(v);
  r.mutable_camera()->set_vertical_fov_rad(static_cast<float>(camera.vertical_fov_rad));
  const auto response = client.render_thumbnail(r);
  ASSERT_TRUE(response.pose.has_value());
  EXPECT_EQ(response.pose->status, evaluated.status);
  EXPECT_TRUE(response.pose->points.empty()) << "the thumbnail's pose carries no points";
  const render::Image image = decode(response);
  ASSERT_EQ(image.width, 320);

  // The dots are drawn over everything in the default key-point colour (yellow: red and green
  // high, blue low), which neither the grey arm nor the blue background has.
  const render::Scene defaults;
  const Eigen::Vector3f key_colour = defaults.key_point_colour * 255.0f;
  for (size_t k = 0; k < keys.indices.size(); ++k) {
    const Eigen::Vector3d p = estimate.row(keys.indices[k]).cast<double>().transpose();
    const auto projected = render::project_to_pixel(camera, 320, 240, p);
    const int x = static_cast<int>(projected.pixel.x());
    const int y = static_cast<int>(projected.pixel.y());
    ASSERT_TRUE(x >= 0 && x < 320 && y >= 0 && y < 240) << "key point " << k << " projects outside";
    const uint8_t* px = image.pixel(x, y);
    EXPECT_NEAR(px[0], key_colour.x(), 2) << "key point " << k << " at (" << x << ", " << y << ")";
    EXPECT_NEAR(px[1], key_colour.y(), 2) << "key point " << k;
    EXPECT_NEAR(px[2], key_colour.z(), 2) << "key point " << k;
  }
}

// `animspace thumbnail --heat`: the CLI prints the largest error and the scale (the model's error
// tolerance, read here from the file), and the PNG it writes carries the legend bar.
TEST_F(RenderServiceTest, TheThumbnailCommandSaysTheHeatScaleAndDrawsItsLegend) {
  auto daemon = start();
  Client client(daemon->address());
  const std::string model = std::string(demo::kDemoPmscModelName);
  auto pmsc_file = container::read_file(repo_->path() / model / "1" / "model.anim");
  ASSERT_TRUE(pmsc_file.ok());
  const double tolerance = std::stod(pmsc_file->metadata_value("pmsc.options.error_tolerance"));
  const auto sequence = repo_->path() / "arm" / "1" / "model.anim";
  auto stored = container::read_file(sequence);
  ASSERT_TRUE(stored.ok());
  auto frames = stored->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());
  const int frame = 7;
  const auto keys = client.describe_key_points(model);
  const std::span<const float> full(frames->row(frame).data(), static_cast<size_t>(frames->cols()));
  const std::vector<float> key_values = keys.gather(full);
  const PoseResult evaluated = client.evaluate_key_points(model, {key_values, keys.channel_count});
  double largest = 0;
  for (uint32_t p = 0; p < evaluated.points.point_count; ++p) {
    double squared = 0;
    for (uint32_t c = 0; c < 3; ++c) {
      const double d = double(evaluated.points.point(p)[c]) - full[3 * p + c];
      squared += d * d;
    }
    largest = std::max(largest, std::sqrt(squared));
  }

  const auto png = work_.path() / "heat.png";
  const std::string command = harness::program_path("animspace").string() + " -s " + daemon->address() + " thumbnail " + model +
                              " -o " + png.string() + " --sequence " + sequence.string() +
                              " --sequence-frame 7 --heat --heat-legend --width 256 --height 256";
  std::string out;
  {
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    char buffer[4096];
    size_t n = 0;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
    ASSERT_EQ(pclose(pipe), 0) << out;
  }
  // "heat map: largest |full − returned| 0.01234, red at 0.02 (…)": 4 significant digits each.
  const std::string lead = "heat map: largest |full − returned| ";
  const auto at = out.find(lead);
  ASSERT_NE(at, std::string::npos) << out;
  const auto red = out.find(", red at ", at);
  ASSERT_NE(red, std::string::npos) << out;
  EXPECT_NEAR(std::stod(out.substr(at + lead.size())), largest, 1e-3 * largest) << out;
  EXPECT_NEAR(std::stod(out.substr(red + 9)), tolerance, 1e-3 * tolerance) << out;

  const auto bytes = read_whole_file(png);
  ASSERT_TRUE(bytes.ok());
  auto image = render::decode_png(*bytes, "heat.png");
  ASSERT_TRUE(image.ok()) << image.error().message;
  expect_legend_bar(*image, tolerance);
}

// issue #39: `relight --heat` had no scale. The scale asked for is the one reported and drawn:
// the legend's bar runs from blue at 0 to red at --heat-max; without one, the scale the server
// chose is printed beside the largest error.
TEST_F(RenderServiceTest, RelightHeatStatesItsScaleAndDrawsItsLegend) {
  TempDir room;  // the demo's Cornell box alone (the suite's repository holds the arm's models)
  ASSERT_TRUE(testing::write_demo_illumination(room.path()).ok());
  auto daemon = std::make_unique<DaemonProcess>(
      std::vector<std::string>{"--model-repository", room.path().string(), "--renderer", "surfaceless"}, work_.path());
  {
    Client client(daemon->address());
    ASSERT_TRUE(testing::wait_until_serving(client)) << daemon->log();
  }
  const auto png = work_.path() / "relight-heat.png";
  const std::string cli = harness::program_path("animspace").string() + " -s " + daemon->address();
  const std::string relight = " relight cornell --from 0.2 0.44 0.3 --heat --width 256 --height 256 -o " + png.string();
  const auto err = work_.path() / "relight.err";
  const nlohmann::json report =
      testing::json_of(testing::run_command(cli + " --json" + relight + " --heat-max 0.5 --heat-legend", err));
  const auto& frame = report.at("frames").at(0);
  const std::string out = report.dump();
  EXPECT_FLOAT_EQ(frame.at("heat_scale_max").get<float>(), 0.5f) << out;
  EXPECT_TRUE(frame.at("heat_legend_drawn").get<bool>()) << out;
  EXPECT_GE(frame.at("heat_max_error").get<double>(), 0.0) << out;
  const auto bytes = read_whole_file(png);
  ASSERT_TRUE(bytes.ok());
  auto image = render::decode_png(*bytes, "relight-heat.png");
  ASSERT_TRUE(image.ok()) << image.error().message;
  expect_legend_bar(*image, 0.5);

  const testing::CliRun run = testing::run_command(cli + relight, err);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::string& plain = run.out;
  EXPECT_NE(plain.find("heat map: largest |full − served| "), std::string::npos) << plain;
  EXPECT_NE(plain.find(", red at "), std::string::npos) << plain;
}

TEST_F(RenderServiceTest, PixelToleranceDrawsTheLevelEquation72Allows) {
  auto daemon = start();
  Client client(daemon->address());
  const std::string model = std::string(demo::kDemoAnimationSpaceModelName);
  auto stored = container::read_file(repo_->path() / model / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  auto skinned = animation_space::load(*stored, "arm-animspace");
  ASSERT_TRUE(skinned.ok());
  auto levels = lod::load_levels(*stored, *skinned, "arm-animspace");
  ASSERT_TRUE(levels.ok());
  ASSERT_GT(levels->count(), 2);

  // The rest pose, the camera the server frames it with, and eq. 7.2 for that camera.
  PointMatrix rest;
  animation_space::evaluate(*skinned, animation_space::rest_pose(skinned->skeleton), rest);
  const int width = 200, height = 100;
  const double aspect = double(width) / height;
  auto camera = render::frame_bounding_box(rest, aspect);
  ASSERT_TRUE(camera.ok());
  const Eigen::Vector3f centre = (rest.colwise().minCoeff() + rest.colwise().maxCoeff()) / 2;
  const double radius = (rest.rowwise() - centre.transpose()).rowwise().norm().maxCoeff();

  int coarsest_seen = 0;
  for (float tolerance : {0.0f, 0.5f, 2.0f, 8.0f, 40.0f}) {
    SCOPED_TRACE(tolerance);
    int expected = 0;
    if (tolerance > 0) {
      lod::PixelTolerance view;
      view.tolerance_px = tolerance;
      view.viewport_width_px = width;
      view.horizontal_fov_rad = render::horizontal_fov(*camera, aspect);
      view.distance = (camera->eye - centre.cast<double>()).norm();
      auto choice = lod::level_for_view(*levels, view, radius);
      ASSERT_TRUE(choice.ok());
      expected = choice->level;
    }
    auto r = request(model, width, height);
    r.set_tolerance_px(tolerance);
    const auto response = client.render_thumbnail(r);
    EXPECT_EQ(static_cast<int>(response.lod_level), expected);
    // A client of 0.1 sends the same quantity as field 14, pixel_tolerance: still honoured.
    auto old_client = request(model, width, height);
    old_client.set_pixel_tolerance(tolerance);
    EXPECT_EQ(static_cast<int>(client.render_thumbnail(old_client).lod_level), expected);
    coarsest_seen = std::max(coarsest_seen, expected);
    const render::Image image = decode(response);
    EXPECT_FALSE(is_background(image, width / 2, height / 2));
  }
  EXPECT_GT(coarsest_seen, 0) << "no tolerance chose a coarser level: the test proves nothing";
}

TEST_F(RenderServiceTest, BadRequestsAreRefusedPreciselyAndTheRenderThreadCarriesOn) {
  auto daemon = start({"--max-thumbnail-px", "1024"});
  Client client(daemon->address());
  using Code = grpc::StatusCode;
  const auto render = [&](v1::RenderThumbnailRequest r) { return [&client, r] { client.render_thumbnail(r); }; };

  expect_refused(render(request("arm", 0, 64)), Code::INVALID_ARGUMENT, "width_px: expected 1..1024");
  expect_refused(render(request("arm", 64, 1025)), Code::INVALID_ARGUMENT, "height_px: expected 1..1024");
  expect_refused(render(request("no-such-model", 64, 64)), Code::NOT_FOUND, "no-such-model");
  expect_refused(render(request("../arm", 64, 64)), Code::INVALID_ARGUMENT, "model.name");
  {
    auto r = request("arm", 64, 64);
    r.set_samples(3);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "samples: expected 1, 2, 4 or 8");
  }
  {
    auto r = request("arm", 64, 64);
    r.clear_background_rgba();
    r.add_background_rgba(1);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "background_rgba: expected 4 values");
  }
  {
    auto r = request("arm", 64, 64);
    for (float v : {0.0f, 0.0f, 5.0f}) r.mutable_camera()->add_eye(v);
    for (float v : {0.0f, 0.0f, 0.0f}) r.mutable_camera()->add_target(v);
    for (float v : {0.0f, 0.0f, 1.0f}) r.mutable_camera()->add_up(v);
    r.mutable_camera()->set_vertical_fov_rad(0.7f);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "camera.up");
  }
  {
    auto r = request("arm", 64, 64);
    r.mutable_camera()->add_eye(1);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "camera.eye: expected 3 values, got 1");
  }
  {
    auto r = request("arm", 64, 64);
    r.set_sequence_frame(100000);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "sequence_frame: expected 0..");
  }
  {
    auto r = request("arm-animspace", 64, 64);
    r.set_show_key_points(true);
    expect_refused(render(r), Code::FAILED_PRECONDITION, "show_key_points");
  }
  {
    auto r = request("arm", 64, 64);
    r.mutable_full_values()->set_point_count(3);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "full_values");
  }
  {
    auto r = request("arm-pmsc", 64, 64);
    r.mutable_key_points()->mutable_key_values()->set_point_count(2);
    r.mutable_key_points()->mutable_key_values()->set_channel_count(3);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "key_points.key_values.point_count");
  }
  {
    auto r = request("arm-animspace", 64, 64);
    r.set_tolerance_px(-1);
    expect_refused(render(r), Code::INVALID_ARGUMENT, "tolerance_px: expected a finite value");
    r.set_tolerance_px(2);
    r.set_pixel_tolerance(3);
    expect_refused(render(r), Code::INVALID_ARGUMENT,
                   "tolerance_px: 2 disagrees with pixel_tolerance (its deprecated name), 3");
  }

  // The render thread is still there and still draws what it drew before.
  const auto first = client.render_thumbnail(request("arm", 64, 64));
  const auto again = client.render_thumbnail(request("arm", 64, 64));
  EXPECT_EQ(first.png, again.png);
  EXPECT_EQ(decode(again).width, 64);
}

TEST_F(RenderServiceTest, AFullRenderQueueAnswersResourceExhaustedAtOnce) {
  auto daemon = start({"--render-queue-depth", "1", "--work-threads", "4"});
  Client client(daemon->address());
  // Large, multisampled thumbnails sent at once: one is drawn, one waits, the rest find the
  // queue full.
  std::vector<std::future<grpc::StatusCode>> calls;
  for (int i = 0; i < 8; ++i) {
    calls.push_back(std::async(std::launch::async, [&client] {
      auto r = request("arm-animspace", 2048, 2048);
      r.set_samples(4);
      try {
        client.render_thumbnail(r);
        return grpc::StatusCode::OK;
      } catch (const RpcError& e) {
        if (e.code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
          EXPECT_NE(e.server_message().find("--render-queue-depth"), std::string::npos) << e.what();
        } else {
          ADD_FAILURE() << e.what();
        }
        return e.code();
      }
    }));
  }
  int ok = 0, exhausted = 0;
  for (auto& call : calls) {
    const auto code = call.get();
    ok += code == grpc::StatusCode::OK;
    exhausted += code == grpc::StatusCode::RESOURCE_EXHAUSTED;
  }
  EXPECT_GE(ok, 1);
  EXPECT_GE(exhausted, 1);
  EXPECT_EQ(ok + exhausted, 8);
  // Once the queue drains, thumbnails are drawn again.
  EXPECT_EQ(decode(client.render_thumbnail(request("arm", 32, 32))).width, 32);
}

TEST_F(RenderServiceTest, WithoutARendererThumbnailsAreUnavailableAndEverythingElseServes) {
  auto daemon = start({"--renderer", "none"});
  Client client(daemon->address());
  const auto info = client.server_info();
  EXPECT_EQ(info.renderer().rfind("none", 0), 0u) << info.renderer();
  for (const auto& rpc : info.implemented_rpcs()) EXPECT_EQ(rpc.find("RenderThumbnail"), std::string::npos);
  expect_refused([&] { client.render_thumbnail(request("arm", 64, 64)); }, grpc::StatusCode::UNAVAILABLE,
                 "--renderer none");
  EXPECT_EQ(client.list_models().size(), 5u);
}

}  // namespace
}  // namespace animspace
