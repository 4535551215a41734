// RenderThumbnail's texture checker (issue #37) against the real animspaced: arm-smooth, the demo
// model with a texture atlas, drawn with its atlas as a checker. The picture is checked through
// what the test computes itself: each pixel's ray (testing::Pinhole, not the renderer's camera)
// cast against the posed mesh, the atlas's UV at the hit interpolated by the hit's barycentric
// coordinates, and the square that UV falls in. With Lambert shading a pixel is albedo × light, so
// the checker's pixel divided by the plain surface's pixel is the checker colour over the plain
// albedo, whatever the light: 0.92 / 0.80 on even squares, 0.20 / 0.80 on odd ones.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/atlas/atlas_io.h"
#include "core/common/atomic_file.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/geometry/bounding_sphere.h"
#include "core/render/png.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/core/render/render_test_geometry.h"
#include "tests/support/cli_run.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using render::testing::Pinhole;
using testing::TempDir;

const std::string kSmooth(demo::kDemoSmoothModelName);
constexpr int kSquares = 8;
constexpr int kSize = 160;

class RenderCheckerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repo_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(repo_->path()).ok());
    ASSERT_TRUE(testing::write_demo_smooth(repo_->path()).ok());
  }
  static void TearDownTestSuite() {
    delete repo_;
    repo_ = nullptr;
  }

  std::unique_ptr<DaemonProcess> start() {
    auto daemon = std::make_unique<DaemonProcess>(
        std::vector<std::string>{"--model-repository", repo_->path().string(), "--miss-log-dir", work_.path().string(),
                                 "--renderer", "surfaceless"},
        work_.path());
    Client client(daemon->address());
    EXPECT_TRUE(testing::wait_until_serving(client)) << "never SERVING\n" << daemon->log();
    return daemon;
  }

  static std::filesystem::path smooth_file() { return repo_->path() / kSmooth / "1" / "model.anim"; }

  static inline TempDir* repo_ = nullptr;
  TempDir work_;
};

render::Image decode(const std::string& png) {
  auto image = render::decode_png(png, "thumbnail");
  EXPECT_TRUE(image.ok()) << image.error().message;
  return image.ok() ? std::move(*image) : render::Image{};
}

// Möller–Trumbore: the nearest hit of the ray with the mesh, as (face, barycentric b1, b2).
struct Hit {
  Eigen::Index face = -1;
  double b1 = 0, b2 = 0;
};
std::optional<Hit> cast(const PointMatrix& V, const FaceMatrix& F, const Eigen::Vector3d& origin,
                        const Eigen::Vector3d& direction) {
  std::optional<Hit> nearest;
  double nearest_t = std::numeric_limits<double>::infinity();
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)).cast<double>().transpose();
    const Eigen::Vector3d e1 = V.row(F(f, 1)).cast<double>().transpose() - a;
    const Eigen::Vector3d e2 = V.row(F(f, 2)).cast<double>().transpose() - a;
    const Eigen::Vector3d p = direction.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-14) continue;
    const Eigen::Vector3d s = origin - a;
    const double b1 = s.dot(p) / det;
    if (b1 < 0 || b1 > 1) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double b2 = direction.dot(q) / det;
    if (b2 < 0 || b1 + b2 > 1) continue;
    const double t = e2.dot(q) / det;
    if (t > 0 && t < nearest_t) {
      nearest_t = t;
      nearest = Hit{f, b1, b2};
    }
  }
  return nearest;
}

v1::RenderThumbnailRequest checker_request(const std::string& model, const render::Camera& camera) {
  v1::RenderThumbnailRequest r;
  r.mutable_model()->set_name(model);
  r.set_width_px(kSize);
  r.set_height_px(kSize);
  r.set_samples(1);
  r.set_shading(v1::RenderThumbnailRequest::SHADING_LAMBERT);
  for (float c : {0.0f, 0.0f, 1.0f, 1.0f}) r.add_background_rgba(c);
  auto* view = r.mutable_camera();
  for (int k = 0; k < 3; ++k) {
    view->add_eye(static_cast<float>(camera.eye[k]));
    view->add_target(static_cast<float>(camera.target[k]));
    view->add_up(static_cast<float>(camera.up[k]));
  }
  view->set_vertical_fov_rad(static_cast<float>(camera.vertical_fov_rad));
  r.set_texture_checker(true);
  r.set_checker_squares(kSquares);
  return r;
}

TEST_F(RenderCheckerTest, EachPixelHasTheColourOfTheSquareItsRayHitsInTheAtlas) {
  // The posed mesh and its atlas, read from the file the daemon serves.
  auto file = container::read_file(smooth_file());
  ASSERT_TRUE(file.ok()) << file.error().message;
  auto model = animation_space::load(*file, "arm-smooth");
  ASSERT_TRUE(model.ok()) << model.error().message;
  auto atlas = atlas::load_atlas(*file, model->faces.rows(), "arm-smooth");
  ASSERT_TRUE(atlas.ok() && atlas->has_value());
  const atlas::CornerUvs& uvs = (*atlas)->uvs;
  PointMatrix V;
  animation_space::evaluate(*model, animation_space::rest_pose(model->skeleton), V);
  const FaceMatrix& F = model->faces;

  // Seen from the side the arm is longest across, at 2.2 radii.
  const geometry::BoundingSphere sphere = geometry::bounding_sphere(V);
  const Eigen::Vector3d extent = (V.colwise().maxCoeff() - V.colwise().minCoeff()).cast<double>().transpose();
  Eigen::Index longest = 0;
  extent.maxCoeff(&longest);
  const Eigen::Vector3d side = Eigen::Vector3d::Unit((longest + 2) % 3);
  const Eigen::Vector3d up = Eigen::Vector3d::Unit((longest + 1) % 3);
  const render::Camera camera =
      render::testing::make_camera(sphere.centre + 2.2 * sphere.radius * side, sphere.centre, up, 0.9);
  const Pinhole pinhole(camera.eye, camera.target, camera.up, camera.vertical_fov_rad, kSize, kSize);

  auto daemon = start();
  Client client(daemon->address());
  v1::RenderThumbnailRequest request = checker_request(kSmooth, camera);
  const render::Image checker = decode(client.render_thumbnail(request).png);
  request.set_texture_checker(false);
  request.set_checker_squares(0);
  const render::Image plain = decode(client.render_thumbnail(request).png);
  ASSERT_EQ(checker.width, kSize);
  ASSERT_EQ(plain.width, kSize);

  // The square (i, j) a ray falls in, if it hits the mesh.
  const auto square_of = [&](double x, double y) -> std::optional<std::array<long, 2>> {
    const std::optional<Hit> hit = cast(V, F, pinhole.eye, pinhole.ray(x, y));
    if (!hit) return std::nullopt;
    const Eigen::Index c = 3 * hit->face;
    const Eigen::Vector2d uv =
        (1 - hit->b1 - hit->b2) * uvs.row(c).transpose() + hit->b1 * uvs.row(c + 1).transpose() + hit->b2 * uvs.row(c + 2).transpose();
    return std::array<long, 2>{static_cast<long>(std::floor(kSquares * uv.x())),
                               static_cast<long>(std::floor(kSquares * uv.y()))};
  };
  const double even_ratio = 0.92 / 0.80, odd_ratio = 0.20 / 0.80;  // Checker's colours over Material's albedo
  int compared = 0, wrong = 0, even = 0;
  for (int y = 1; y < kSize; y += 3) {
    for (int x = 1; x < kSize; x += 3) {
      // Only pixels whose centre and corners all fall in one square of one surface.
      const auto centre = square_of(x + 0.5, y + 0.5);
      if (!centre) continue;
      bool inside = true;
      for (const auto& [dx, dy] : std::vector<std::array<double, 2>>{{0.05, 0.05}, {0.95, 0.05}, {0.05, 0.95}, {0.95, 0.95}}) {
        inside = inside && square_of(x + dx, y + dy) == centre;
      }
      if (!inside) continue;
      const bool expect_even = ((*centre)[0] + (*centre)[1]) % 2 == 0;
      const double lit = plain.pixel(x, y)[0];
      if (lit < 40) continue;  // too dark for an 8-bit ratio
      const double ratio = checker.pixel(x, y)[0] / lit;
      const double expected = expect_even ? even_ratio : odd_ratio;
      ++compared;
      even += expect_even ? 1 : 0;
      if (std::abs(ratio - expected) > 1.5 / lit + 0.01 && ++wrong <= 5) {
        ADD_FAILURE() << "pixel (" << x << ", " << y << "): square (" << (*centre)[0] << ", " << (*centre)[1] << "), "
                      << (expect_even ? "even" : "odd") << ", checker/plain " << ratio << ", expected " << expected;
      }
    }
  }
  EXPECT_EQ(wrong, 0) << "of " << compared << " pixels";
  EXPECT_GT(compared, 200);
  EXPECT_GT(even, compared / 5);
  EXPECT_LT(even, compared - compared / 5);

  // Chart borders: the overlay's flat colour appears only when asked for.
  const auto border_pixels = [&](bool borders) {
    v1::RenderThumbnailRequest r = checker_request(kSmooth, camera);
    r.set_show_chart_borders(borders);
    const render::Image image = decode(client.render_thumbnail(r).png);
    int count = 0;
    for (int py = 0; py < image.height; ++py) {
      for (int px = 0; px < image.width; ++px) {
        const uint8_t* p = image.pixel(px, py);
        // Checker::chart_border_colour (0.85, 0.10, 0.10), unlit: 216.75 and 25.5 before rounding.
        count += std::abs(p[0] - 217) <= 1 && std::abs(p[1] - 25.5) <= 1 && std::abs(p[2] - 25.5) <= 1;
      }
    }
    return count;
  };
  EXPECT_EQ(border_pixels(false), 0);
  EXPECT_GT(border_pixels(true), 50);
}

TEST_F(RenderCheckerTest, RefusalsNameTheFieldAndTheModel) {
  auto daemon = start();
  Client client(daemon->address());
  const render::Camera camera = render::testing::make_camera({0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 0.8);
  const auto refused = [&](const v1::RenderThumbnailRequest& r, grpc::StatusCode code, const std::string& part) {
    try {
      client.render_thumbnail(r);
      ADD_FAILURE() << "expected " << status_code_name(code) << " containing '" << part << "', got OK";
    } catch (const RpcError& e) {
      EXPECT_EQ(e.code(), code) << e.server_message();
      EXPECT_NE(e.server_message().find(part), std::string::npos) << e.server_message();
    }
  };
  // A model without an atlas: how to make one.
  refused(checker_request("arm-animspace", camera), grpc::StatusCode::FAILED_PRECONDITION,
          "texture_checker: model 'arm-animspace' version 1 stores no texture atlas");
  refused(checker_request("arm-animspace", camera), grpc::StatusCode::FAILED_PRECONDITION, "`animspace atlas");

  v1::RenderThumbnailRequest r = checker_request(kSmooth, camera);
  r.set_checker_squares(-3);
  refused(r, grpc::StatusCode::INVALID_ARGUMENT,
          "checker_squares: expected > 0 squares per unit of texture coordinate (0: the default 16), got -3");
  r = checker_request(kSmooth, camera);
  r.set_texture_checker(false);
  refused(r, grpc::StatusCode::INVALID_ARGUMENT, "checker_squares: needs texture_checker");
  r = checker_request(kSmooth, camera);
  r.set_texture_checker(false);
  r.set_checker_squares(0);
  r.set_show_chart_borders(true);
  refused(r, grpc::StatusCode::INVALID_ARGUMENT, "show_chart_borders: needs texture_checker");

  // The default square count is 16: the same picture as asking for 16.
  r = checker_request(kSmooth, camera);
  r.set_checker_squares(0);
  const std::string by_default = client.render_thumbnail(r).png;
  r.set_checker_squares(16);
  EXPECT_EQ(decode(by_default).rgba, decode(client.render_thumbnail(r).png).rgba);
  r.set_checker_squares(4);
  EXPECT_NE(decode(by_default).rgba, decode(client.render_thumbnail(r).png).rgba);
}

TEST_F(RenderCheckerTest, TheThumbnailCommandDrawsTheCheckerAndRefusesWithoutAnAtlas) {
  auto daemon = start();
  Client client(daemon->address());
  const std::string cli = harness::program_path("animspace").string() + " -s " + daemon->address() + " thumbnail ";
  const auto png = work_.path() / "checker.png";
  const auto err = work_.path() / "err.txt";

  testing::CliRun run = testing::run_command(
      cli + kSmooth + " -o " + png.string() + " --checker --checker-squares 8 --chart-borders --width 96 --height 80", err);
  ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
  // What the command drew is what the RPC draws for the same request.
  v1::RenderThumbnailRequest r;
  r.mutable_model()->set_name(kSmooth);
  r.set_width_px(96);
  r.set_height_px(80);
  r.set_samples(4);
  r.set_texture_checker(true);
  r.set_checker_squares(8);
  r.set_show_chart_borders(true);
  auto written = read_whole_file(png);
  ASSERT_TRUE(written.ok());
  EXPECT_EQ(decode(*written).rgba, decode(client.render_thumbnail(r).png).rgba);

  run = testing::run_command(cli + "arm-animspace -o " + png.string() + " --checker", err);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("FAILED_PRECONDITION"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("`animspace atlas"), std::string::npos) << run.err;

  run = testing::run_command(cli + kSmooth + " -o " + png.string() + " --checker --checker-squares 0", err);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("--checker-squares"), std::string::npos) << run.err;
  run = testing::run_command(cli + kSmooth + " -o " + png.string() + " --checker-squares 8", err);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("--checker"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace animspace
