// Tests of the EGL renderer (core/render/renderer.h) on Mesa's surfaceless platform (or the
// platform named by $ANIMSPACE_TEST_EGL_PLATFORM).
//
// Every expectation comes from geometry computed here: which pixels a sphere or a cube covers
// (ray casting and projected hulls through testing::Pinhole), what the shading model of scene.h
// gives at a point whose normal is known, where a key point projects. Pixels within one pixel of
// a silhouette are left out: rasterisation there depends on sub-pixel tie-breaking.
#include "core/render/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/render/camera.h"
#include "core/render/png.h"
#include "tests/core/render/render_test_geometry.h"

namespace animspace::render {
namespace {

using testing::make_camera;

using testing::Pinhole;

using Rgb = std::array<int, 3>;

Rgb rgb(const Image& image, int x, int y) {
  const uint8_t* p = image.pixel(x, y);
  return {p[0], p[1], p[2]};
}

Rgb to_rgb8(const Eigen::Vector3f& colour) {
  Rgb out;
  for (int c = 0; c < 3; ++c) out[static_cast<size_t>(c)] = static_cast<int>(std::lround(255 * std::clamp(colour[c], 0.0f, 1.0f)));
  return out;
}

bool is_background(const Image& image, int x, int y) {
  const uint8_t* p = image.pixel(x, y);
  return p[0] == 0 && p[1] == 0 && p[2] == 0;
}

// Whether some pixel in the 3 × 3 block around (x, y) has exactly `colour`.
bool colour_near(const Image& image, int x, int y, const Rgb& colour) {
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      const int u = x + dx, v = y + dy;
      if (u >= 0 && v >= 0 && u < image.width && v < image.height && rgb(image, u, v) == colour) return true;
    }
  }
  return false;
}

Pinhole pinhole(const Scene& scene) {
  const Camera& c = *scene.camera;
  return Pinhole(c.eye, c.target, c.up, c.vertical_fov_rad, scene.width, scene.height);
}

// A unit icosphere (20 480 triangles) seen head-on from (0, 0, 4) on a black background.
Scene sphere_scene(int width, int height, int subdivisions = 5) {
  const TriangleMesh mesh = testing::icosphere(subdivisions);
  Scene scene;
  scene.width = width;
  scene.height = height;
  scene.points = mesh.V;
  scene.faces = mesh.F;
  scene.camera = make_camera({0, 0, 4}, {0, 0, 0}, {0, 1, 0}, 0.8);
  scene.background = Eigen::Vector4f(0, 0, 0, 1);
  scene.samples = 1;
  return scene;
}

// The platform the suite renders on: surfaceless (Mesa llvmpipe without a GPU), or the one named
// by $ANIMSPACE_TEST_EGL_PLATFORM ("device" runs the same checks on a GPU).
EglPlatform test_platform() {
  const char* name = std::getenv("ANIMSPACE_TEST_EGL_PLATFORM");
  if (name == nullptr) return EglPlatform::kSurfaceless;
  Result<EglPlatform> platform = parse_egl_platform(name);
  return platform.ok() ? *platform : EglPlatform::kSurfaceless;
}

class RenderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result<std::unique_ptr<Renderer>> made = make_egl_renderer(test_platform());
    if (made.ok()) {
      renderer_ = std::move(*made).release();
    } else {
      open_error_ = new std::string(made.error().message);
    }
  }
  static void TearDownTestSuite() {
    delete renderer_;
    renderer_ = nullptr;
    delete open_error_;
    open_error_ = nullptr;
  }
  void SetUp() override {
    if (renderer_ == nullptr) GTEST_SKIP() << "no EGL display: " << *open_error_;
  }

  static Image render_ok(const Scene& scene) {
    Result<Image> image = renderer_->render(scene);
    EXPECT_TRUE(image.ok()) << image.error().message;
    if (!image.ok()) return Image();
    EXPECT_EQ(image->width, scene.width);
    EXPECT_EQ(image->height, scene.height);
    EXPECT_EQ(image->rgba.size(), 4 * static_cast<size_t>(scene.width) * static_cast<size_t>(scene.height));
    return std::move(*image);
  }

  static Error render_error(const Scene& scene) {
    Result<Image> image = renderer_->render(scene);
    EXPECT_FALSE(image.ok());
    return image.ok() ? Error{} : image.error();
  }

  static inline Renderer* renderer_ = nullptr;
  static inline std::string* open_error_ = nullptr;
};

TEST_F(RenderTest, DescriptionNamesThePlatformAndTheGlImplementation) {
  const std::string description = renderer_->description();
  EXPECT_EQ(description.rfind(std::string("EGL ") + egl_platform_name(test_platform()) + " — ", 0), 0u) << description;
  EXPECT_NE(description.find("OpenGL ES 3"), std::string::npos) << description;
}

TEST_F(RenderTest, SphereCoversExactlyThePixelsWhoseRaysHitIt) {
  // Non-square on purpose: the silhouette must stay a circle, not an ellipse.
  const Scene scene = sphere_scene(200, 150);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  // The silhouette is the cone of half-angle asin(1/4) around the axis: a circle about the image
  // centre of radius tan(asin(1/4)) / tan(fov/2) half-heights. (The inscribed polyhedron's
  // silhouette lies within 0.02 px of it at this tessellation.)
  const double radius_px = std::tan(std::asin(0.25)) / camera.tan_half * scene.height / 2;
  int checked = 0, covered = 0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const double distance = std::abs(std::hypot(x + 0.5 - scene.width / 2.0, y + 0.5 - scene.height / 2.0) - radius_px);
      if (distance <= 1.0) continue;
      const bool hit = testing::hit_sphere(camera.eye, camera.pixel_ray(x, y), Eigen::Vector3d::Zero(), 1).has_value();
      ASSERT_EQ(!is_background(image, x, y), hit) << "pixel (" << x << ", " << y << ")";
      ++checked;
      covered += hit ? 1 : 0;
    }
  }
  EXPECT_GT(checked, scene.width * scene.height * 9 / 10);
  // Pixel centres more than a pixel inside the circle: about π(R − 1)².
  const double pi = std::numbers::pi;
  EXPECT_NEAR(covered, pi * (radius_px - 1) * (radius_px - 1), pi * radius_px);
}

// Andrew's monotone chain: the convex hull counter-clockwise in (x, y).
std::vector<Eigen::Vector2d> convex_hull(std::vector<Eigen::Vector2d> points) {
  std::sort(points.begin(), points.end(),
            [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  const auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  std::vector<Eigen::Vector2d> hull(2 * points.size());
  size_t k = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
    hull[k++] = points[i];
  }
  for (size_t i = points.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
    hull[k++] = points[i];
  }
  hull.resize(k - 1);
  return hull;
}

double segment_distance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return (p - (a + t * (b - a))).norm();
}

TEST_F(RenderTest, RotatedCubeCoversItsProjectedHull) {
  const TriangleMesh cube = testing::cube();
  const Eigen::Matrix3f rotation = Eigen::AngleAxisf(0.6f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();
  Scene scene;
  scene.width = 240;
  scene.height = 180;
  scene.points = cube.V * rotation.transpose();
  scene.faces = cube.F;
  scene.camera = make_camera({0.4, 0.3, 7}, {0.1, -0.2, 0}, {0.1, 1, 0}, 0.7);
  scene.background = Eigen::Vector4f(0, 0, 0, 1);
  scene.samples = 1;
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());

  // A convex body's silhouette is the convex hull of its projected corners.
  const Pinhole camera = pinhole(scene);
  std::vector<Eigen::Vector2d> corners;
  for (Eigen::Index i = 0; i < scene.points.rows(); ++i) {
    corners.push_back(camera.project(scene.points.row(i).cast<double>().transpose()));
  }
  const std::vector<Eigen::Vector2d> hull = convex_hull(corners);
  ASSERT_GE(hull.size(), 4u);
  // Image y runs down, so "counter-clockwise in (x, y)" has the inside on the left in that frame.
  int covered = 0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const Eigen::Vector2d p(x + 0.5, y + 0.5);
      bool inside = true;
      double distance = std::numeric_limits<double>::infinity();
      for (size_t k = 0; k < hull.size(); ++k) {
        const Eigen::Vector2d& a = hull[k];
        const Eigen::Vector2d& b = hull[(k + 1) % hull.size()];
        inside = inside && (b - a).x() * (p - a).y() - (b - a).y() * (p - a).x() >= 0;
        distance = std::min(distance, segment_distance(p, a, b));
      }
      if (distance <= 1.0) continue;
      ASSERT_EQ(!is_background(image, x, y), inside) << "pixel (" << x << ", " << y << ")";
      covered += inside ? 1 : 0;
    }
  }
  EXPECT_GT(covered, 1000);
}

// The shading model of scene.h at a point where n·l is `nl`.
Eigen::Vector3f expected_colour(const Material& material, Shading shading, double nl) {
  Eigen::Vector3f c = material.albedo * static_cast<float>(material.ambient + material.diffuse * nl);
  if (shading == Shading::kBlinnPhong) {
    c += Eigen::Vector3f::Constant(static_cast<float>(material.specular * std::pow(nl, material.shininess)));
  }
  return c;
}

void expect_colour_near(const Rgb& actual, const Rgb& expected, int tolerance, const std::string& where) {
  for (size_t c = 0; c < 3; ++c) {
    EXPECT_NEAR(actual[c], expected[c], tolerance) << where << ", channel " << c;
  }
}

TEST_F(RenderTest, ShadingMatchesTheDocumentedModel) {
  // Odd size: the centre pixel's ray is the view axis, where n = l.
  Scene scene = sphere_scene(201, 201);
  scene.material.albedo = Eigen::Vector3f(0.6f, 0.5f, 0.4f);
  scene.material.ambient = 0.1f;
  scene.material.diffuse = 0.7f;
  scene.material.specular = 0.2f;
  scene.material.shininess = 16;
  const Pinhole camera = pinhole(scene);

  // On the centre row, the pixel whose ray meets the sphere where its normal makes 60° with the
  // direction to the eye (n·v = n·l = 1/2).
  int probe = -1;
  double probe_nl = 0;
  for (int x = 100; x < scene.width; ++x) {
    const Eigen::Vector3d ray = camera.pixel_ray(x, 100);
    const auto t = testing::hit_sphere(camera.eye, ray, Eigen::Vector3d::Zero(), 1);
    if (!t) break;
    const Eigen::Vector3d p = camera.eye + *t * ray;
    const double nl = p.normalized().dot((camera.eye - p).normalized());
    if (probe < 0 || std::abs(nl - 0.5) < std::abs(probe_nl - 0.5)) {
      probe = x;
      probe_nl = nl;
    }
  }
  ASSERT_GE(probe, 0);
  ASSERT_NEAR(probe_nl, 0.5, 0.02);

  for (const Shading shading : {Shading::kLambert, Shading::kBlinnPhong}) {
    scene.shading = shading;
    for (const bool explicit_normals : {false, true}) {
      SCOPED_TRACE(std::string(shading == Shading::kLambert ? "Lambert" : "Blinn-Phong") +
                   (explicit_normals ? ", exact normals" : ", area-weighted normals"));
      // On a unit sphere the exact normal is the position.
      scene.normals = explicit_normals ? scene.points : PointMatrix();
      const Image image = render_ok(scene);
      ASSERT_FALSE(image.rgba.empty());
      expect_colour_near(rgb(image, 100, 100), to_rgb8(expected_colour(scene.material, shading, 1.0)), 2, "centre");
      expect_colour_near(rgb(image, probe, 100), to_rgb8(expected_colour(scene.material, shading, probe_nl)), 3,
                         "60° pixel");
    }
  }
}

TEST_F(RenderTest, SaturatedHighlightsClampInsteadOfWrapping) {
  Scene scene = sphere_scene(101, 101, 3);
  scene.material.albedo = Eigen::Vector3f(1, 1, 1);
  scene.material.ambient = 0.5f;
  scene.material.diffuse = 1;
  scene.material.specular = 1;
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  EXPECT_EQ(rgb(image, 50, 50), (Rgb{255, 255, 255}));
}

TEST_F(RenderTest, BackFacesAreLitWithTheFlippedNormal) {
  // A square facing away from the eye (normal −z, eye on +z): lit as if it faced the eye.
  Scene scene;
  scene.width = 64;
  scene.height = 64;
  scene.points.resize(4, 3);
  scene.points << -1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0;
  scene.faces.resize(2, 3);
  scene.faces << 0, 2, 1, 0, 3, 2;  // clockwise seen from +z
  scene.camera = make_camera({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, 0.8);
  scene.shading = Shading::kLambert;
  scene.samples = 1;
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  // At the pixel next to the centre n·l is within 1e-4 of 1.
  expect_colour_near(rgb(image, 32, 32), to_rgb8(expected_colour(scene.material, Shading::kLambert, 1.0)), 1, "centre");
}

TEST_F(RenderTest, KeyPointsAreDrawnOnTopAsRoundDots) {
  Scene scene = sphere_scene(256, 256, 3);
  scene.background = Eigen::Vector4f(0.2f, 0.3f, 0.4f, 1);
  scene.samples = 4;
  scene.key_point_radius_px = 6;
  scene.key_point_colour = Eigen::Vector3f(1, 0, 1);
  // The icosahedron's own corners (the first 12 vertices): far apart on screen, some of them on
  // the far side of the sphere, which must show through (Meyer & Anderson 2007, Fig. 1).
  scene.key_points = {0, 1, 4, 5, 6, 9, 11};
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  std::vector<Eigen::Vector2d> centres;
  for (const int32_t v : scene.key_points) centres.push_back(camera.project(scene.points.row(v).cast<double>().transpose()));
  const Rgb magenta{255, 0, 255};
  bool hidden_vertex_seen = false;
  for (size_t k = 0; k < centres.size(); ++k) {
    const Eigen::Vector2d& c = centres[k];
    const int x = static_cast<int>(std::floor(c.x())), y = static_cast<int>(std::floor(c.y()));
    EXPECT_EQ(rgb(image, x, y), magenta) << "key point " << scene.key_points[k];
    hidden_vertex_seen = hidden_vertex_seen || scene.points(scene.key_points[k], 2) < -0.5f;
    // Three radii to the right, unless another dot is near there.
    const Eigen::Vector2d away = c + Eigen::Vector2d(3 * scene.key_point_radius_px, 0);
    const bool crowded = std::any_of(centres.begin(), centres.end(), [&](const Eigen::Vector2d& other) {
      return (other - away).norm() < 2 * scene.key_point_radius_px;
    });
    if (!crowded) {
      EXPECT_NE(rgb(image, static_cast<int>(away.x()), static_cast<int>(away.y())), magenta)
          << "3 radii from key point " << scene.key_points[k];
    }
  }
  EXPECT_TRUE(hidden_vertex_seen);
  // Round, not square: a pixel whose centre is 4.5–5.5 px right of and below a dot's centre is
  // inside the 12 px point sprite (all its samples are) but more than 6 px from the centre.
  for (const Eigen::Vector2d& c : centres) {
    const int x = static_cast<int>(std::floor(c.x() + 5)), y = static_cast<int>(std::floor(c.y() + 5));
    EXPECT_NE(rgb(image, x, y), magenta) << "corner of the dot at (" << c.x() << ", " << c.y() << ")";
  }
}

TEST_F(RenderTest, HeatMapRunsFromBlueThroughGreenToRed) {
  Scene scene = sphere_scene(256, 256, 4);
  scene.heat.resize(scene.points.rows());
  // Three bands across x: 0, heat_max / 3 and heat_max.
  for (Eigen::Index i = 0; i < scene.points.rows(); ++i) {
    const float x = scene.points(i, 0);
    scene.heat[i] = x < -0.35f ? 0.0f : (x > 0.35f ? 3.0f : 1.0f);
  }
  scene.heat_max = 3;
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  const auto probe = [&](double x) {
    const Eigen::Vector2d p = camera.project(Eigen::Vector3d(x, 0, std::sqrt(1 - x * x)));
    return rgb(image, static_cast<int>(p.x()), static_cast<int>(p.y()));
  };
  const Rgb blue = probe(-0.7), green = probe(0), red = probe(0.7);
  EXPECT_GT(blue[2], 2 * std::max(blue[0], blue[1]));
  EXPECT_GT(green[1], 2 * std::max(green[0], green[2]));
  EXPECT_GT(red[0], 2 * std::max(red[1], red[2]));

  // heat_max ≤ 0: the largest value is red.
  scene.heat_max = 0;
  const Image automatic = render_ok(scene);
  ASSERT_FALSE(automatic.rgba.empty());
  EXPECT_EQ(automatic.rgba, image.rgba);
}

// The colour map of scene.h, written out: blue, green, yellow, red at t = 0, 1/3, 2/3, 1.
Eigen::Vector3f heat_map(double t) {
  const Eigen::Vector3f stops[] = {{0, 0, 1}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}};
  const double s = 3 * std::clamp(t, 0.0, 1.0);
  const int k = std::min(static_cast<int>(s), 2);
  return stops[k] + static_cast<float>(s - k) * (stops[k + 1] - stops[k]);
}

TEST_F(RenderTest, HeatColoursFollowTheDocumentedMap) {
  // Ambient 1, no diffuse or specular: the pixel is the albedo, here the heat colour itself.
  Scene scene = sphere_scene(33, 33, 2);
  scene.material.ambient = 1;
  scene.material.diffuse = 0;
  scene.material.specular = 0;
  scene.heat_max = 3;
  for (const double heat : {0.0, 0.25, 0.5, 1.0, 1.4, 2.0, 2.2, 3.0, 4.5}) {
    SCOPED_TRACE(heat);
    scene.heat = Eigen::VectorXf::Constant(scene.points.rows(), static_cast<float>(heat));
    const Image image = render_ok(scene);
    ASSERT_FALSE(image.rgba.empty());
    expect_colour_near(rgb(image, 16, 16), to_rgb8(heat_map(heat / 3)), 1, "centre");
  }
}

// ---------------------------------------------------------------------------------------------
// Per-vertex colours (Scene::vertex_colours, exposure, srgb, Shading::kUnlit).

// The square [−1, 1]² in the plane z = 0, counter-clockwise from +z, seen head-on from (0, 0, 3)
// on a black background: corners 0 (−1, −1), 1 (1, −1), 2 (1, 1), 3 (−1, 1). The plane is
// parallel to the image, so perspective-correct interpolation is affine on screen.
Scene facing_square(int size) {
  Scene scene;
  scene.width = size;
  scene.height = size;
  scene.points.resize(4, 3);
  scene.points << -1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0;
  scene.faces.resize(2, 3);
  scene.faces << 0, 1, 2, 0, 2, 3;
  scene.camera = make_camera({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, 0.8);
  scene.background = Eigen::Vector4f(0, 0, 0, 1);
  scene.samples = 1;
  return scene;
}

// Where the ray through the centre of pixel (x, y) meets the plane z = 0 of facing_square, if
// the pixel centre is more than 1.5 px inside the square's projection (clear of its edges).
std::optional<Eigen::Vector2d> square_point(const Pinhole& camera, int x, int y) {
  const Eigen::Vector3d ray = camera.pixel_ray(x, y);
  const Eigen::Vector3d p = camera.eye - camera.eye.z() / ray.z() * ray;
  const Eigen::Vector2d lower = camera.project(Eigen::Vector3d(-1, 1, 0));  // top-left on screen
  const Eigen::Vector2d upper = camera.project(Eigen::Vector3d(1, -1, 0));
  const double margin = std::min({x + 0.5 - lower.x(), upper.x() - x - 0.5, y + 0.5 - lower.y(), upper.y() - y - 0.5});
  if (margin <= 1.5) return std::nullopt;
  return Eigen::Vector2d(p.x(), p.y());
}

TEST_F(RenderTest, UnlitPixelsAreTheExposedVertexColours) {
  // Every covered pixel is round(255 · clamp(exposure · colour, 0, 1)); 255 · the products are at
  // least 0.15 away from a rounding boundary, so the check is exact.
  struct Case {
    Eigen::Vector3f colour;
    float exposure;
    Rgb expected;
  };
  const Case cases[] = {
      {{0.2f, 0.35f, 0.03f}, 1.0f, {51, 89, 8}},           // 51.0, 89.25, 7.65
      {{6, 1, 0.4f}, 0.125f, {191, 32, 13}},               // 191.25, 31.875, 12.75
      {{2000, 300, 0}, 0.002f, {255, 153, 0}},             // red clamps from 4
      {{1e-4f, 5e-4f, 2e-3f}, 400.0f, {10, 51, 204}},      // radiance on a tiny scale
  };
  Scene scene = facing_square(65);
  scene.shading = Shading::kUnlit;
  scene.material.albedo = Eigen::Vector3f(0, 1, 0);  // must not show
  const Pinhole camera = pinhole(scene);
  for (const Case& c : cases) {
    SCOPED_TRACE("exposure " + std::to_string(c.exposure));
    scene.vertex_colours = c.colour.transpose().replicate(4, 1);
    scene.exposure = c.exposure;
    const Image image = render_ok(scene);
    ASSERT_FALSE(image.rgba.empty());
    int checked = 0;
    for (int y = 0; y < scene.height; ++y) {
      for (int x = 0; x < scene.width; ++x) {
        if (!square_point(camera, x, y)) continue;
        ASSERT_EQ(rgb(image, x, y), c.expected) << "pixel (" << x << ", " << y << ")";
        ++checked;
      }
    }
    EXPECT_GT(checked, 40 * 40);
    EXPECT_TRUE(is_background(image, 0, 0));
  }
}

TEST_F(RenderTest, VertexColoursAreInterpolatedAcrossTheSurface) {
  // Colours that are an affine function of the position, colour(x, y) = b + g_x·x + g_y·y, are
  // reproduced exactly by barycentric interpolation on both triangles; at the centre pixel the
  // value is the average of the corners.
  const Eigen::Vector3f base(0.25f, 0.25f, 0.2f), gx(0.2f, 0, -0.1f), gy(0, 0.1f, 0.05f);
  const float exposure = 2;
  Scene scene = facing_square(65);  // odd: the centre pixel's ray is the view axis
  scene.shading = Shading::kUnlit;
  scene.exposure = exposure;
  scene.vertex_colours.resize(4, 3);
  for (Eigen::Index i = 0; i < 4; ++i) {
    scene.vertex_colours.row(i) = (base + scene.points(i, 0) * gx + scene.points(i, 1) * gy).transpose();
  }
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  const Eigen::Vector3f average = scene.vertex_colours.colwise().mean().transpose();
  expect_colour_near(rgb(image, 32, 32), to_rgb8(exposure * average), 1, "centre");
  int checked = 0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const std::optional<Eigen::Vector2d> p = square_point(camera, x, y);
      if (!p) continue;
      const Eigen::Vector3f expected =
          exposure * (base + static_cast<float>(p->x()) * gx + static_cast<float>(p->y()) * gy);
      const std::string where = "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")";
      expect_colour_near(rgb(image, x, y), to_rgb8(expected), 1, where);
      ++checked;
    }
  }
  EXPECT_GT(checked, 40 * 40);
  // The gradient is visible: the left and right edges differ by 2 · 2 · 0.2 · 255 ≈ 200 in red.
  EXPECT_GT(rgb(image, 52, 32)[0] - rgb(image, 12, 32)[0], 150);
}

TEST_F(RenderTest, LitVertexColoursReplaceTheAlbedo) {
  // Same probes as ShadingMatchesTheDocumentedModel, with a = exposure · colour in place of the
  // material's albedo (set to a colour that would show if it were used).
  Scene scene = sphere_scene(201, 201);
  scene.normals = scene.points;  // on a unit sphere the exact normal is the position
  scene.material.albedo = Eigen::Vector3f(0, 1, 0);
  scene.material.ambient = 0.1f;
  scene.material.diffuse = 0.7f;
  scene.material.specular = 0.2f;
  scene.material.shininess = 16;
  const Eigen::Vector3f colour(0.75f, 0.25f, 0.5f);
  scene.vertex_colours = colour.transpose().replicate(scene.points.rows(), 1);
  scene.exposure = 1.2f;
  Material by_hand = scene.material;
  by_hand.albedo = scene.exposure * colour;

  // The pixel on the centre row whose ray meets the sphere where n·l = 1/2.
  const Pinhole camera = pinhole(scene);
  int probe = -1;
  double probe_nl = 0;
  for (int x = 100; x < scene.width; ++x) {
    const Eigen::Vector3d ray = camera.pixel_ray(x, 100);
    const auto t = testing::hit_sphere(camera.eye, ray, Eigen::Vector3d::Zero(), 1);
    if (!t) break;
    const Eigen::Vector3d p = camera.eye + *t * ray;
    const double nl = p.normalized().dot((camera.eye - p).normalized());
    if (probe < 0 || std::abs(nl - 0.5) < std::abs(probe_nl - 0.5)) {
      probe = x;
      probe_nl = nl;
    }
  }
  ASSERT_GE(probe, 0);
  ASSERT_NEAR(probe_nl, 0.5, 0.02);

  for (const Shading shading : {Shading::kLambert, Shading::kBlinnPhong}) {
    SCOPED_TRACE(shading == Shading::kLambert ? "Lambert" : "Blinn-Phong");
    scene.shading = shading;
    const Image image = render_ok(scene);
    ASSERT_FALSE(image.rgba.empty());
    expect_colour_near(rgb(image, 100, 100), to_rgb8(expected_colour(by_hand, shading, 1.0)), 2, "centre");
    expect_colour_near(rgb(image, probe, 100), to_rgb8(expected_colour(by_hand, shading, probe_nl)), 3, "60° pixel");
  }
}

// IEC 61966-2-1, written out.
float srgb_encode(float c) { return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1 / 2.4f) - 0.055f; }

TEST_F(RenderTest, SrgbEncodesTheSurfaceAfterExposureAndClamping) {
  Scene scene = facing_square(33);
  scene.shading = Shading::kUnlit;
  scene.background = Eigen::Vector4f(0.2f, 0.2f, 0.2f, 1);
  scene.srgb = true;
  // Exposed: 0.002 (on the linear segment), 0.125, and 2.8, which clamps to 1 before the encoding.
  scene.exposure = 4;
  scene.vertex_colours = Eigen::RowVector3f(0.0005f, 0.03125f, 0.7f).replicate(4, 1);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Eigen::Vector3f expected(srgb_encode(0.002f), srgb_encode(0.125f), srgb_encode(1.0f));
  const Rgb expected8 = to_rgb8(expected);
  ASSERT_EQ(expected8, (Rgb{7, 99, 255}));  // independent of the helper: 6.59, 99.09, 255
  expect_colour_near(rgb(image, 16, 16), expected8, 1, "centre");
  // The background is drawn as given.
  EXPECT_EQ(rgb(image, 0, 0), (Rgb{51, 51, 51}));
}

TEST_F(RenderTest, WithoutVertexColoursExposureChangesNothingAndUnlitIsTheAlbedo) {
  Scene scene = sphere_scene(101, 101, 3);
  const Image lit = render_ok(scene);
  scene.exposure = 3;
  EXPECT_EQ(render_ok(scene).rgba, lit.rgba);

  // Unlit: the albedo on every covered pixel, however the surface turns.
  scene.shading = Shading::kUnlit;
  scene.material.albedo = Eigen::Vector3f(0.6f, 0.25f, 0.8f);  // 153, 63.75, 204: clear of rounding ties
  const Image unlit = render_ok(scene);
  ASSERT_FALSE(unlit.rgba.empty());
  for (const int x : {50, 60, 70}) {
    EXPECT_EQ(rgb(unlit, x, 50), to_rgb8(scene.material.albedo)) << "pixel (" << x << ", 50)";
  }

  // Unlit heat map: the heat colour itself (the heat map of HeatColoursFollowTheDocumentedMap).
  scene.heat = Eigen::VectorXf::Constant(scene.points.rows(), 1.4f);
  scene.heat_max = 3;
  const Image heat = render_ok(scene);
  ASSERT_FALSE(heat.rgba.empty());
  expect_colour_near(rgb(heat, 60, 50), to_rgb8(heat_map(1.4 / 3)), 1, "heat");
}

TEST_F(RenderTest, BadVertexColoursAndExposureAreRefusedNamingTheField) {
  const Scene good = sphere_scene(48, 48, 3);
  const Image before = render_ok(good);
  ASSERT_FALSE(before.rgba.empty());
  const Eigen::Index n = good.points.rows();

  Scene scene = good;
  scene.vertex_colours = PointMatrix::Ones(10, 3);
  Error error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "vertex_colours: expected 642 rows (one per point) or none, got 10");

  scene = good;
  scene.vertex_colours = PointMatrix::Constant(n, 3, 0.5f);
  scene.vertex_colours(7, 1) = -0.25f;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "vertex_colours: colour 7: expected finite values ≥ 0, got (0.5, -0.25, 0.5)");

  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    scene = good;
    scene.vertex_colours = PointMatrix::Constant(n, 3, 0.5f);
    scene.vertex_colours(3, 2) = bad;
    error = render_error(scene);
    EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(error.message.rfind("vertex_colours: colour 3: expected finite values ≥ 0, got (0.5, 0.5, ", 0), 0u)
        << error.message;
  }

  scene = good;
  scene.vertex_colours = PointMatrix::Constant(n, 3, 0.5f);
  scene.heat = Eigen::VectorXf::Ones(n);
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "vertex_colours: set together with heat; the surface takes its colour from one of them");

  scene = good;
  scene.exposure = 0;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "exposure: expected a finite value > 0, got 0");

  for (const float bad : {-1.0f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    scene = good;
    scene.exposure = bad;
    error = render_error(scene);
    EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(error.message.rfind("exposure: expected a finite value > 0, got ", 0), 0u) << error.message;
  }

  EXPECT_EQ(render_ok(good).rgba, before.rgba);
}

TEST_F(RenderTest, WireframeIsNotHiddenByTheSurfaceItOutlines) {
  // A flat grid seen obliquely: edges and triangles have the same depth, so without the
  // polygon offset on the filled pass the edges would z-fight with it.
  const int n = 8;
  Scene scene;
  scene.width = 200;
  scene.height = 200;
  scene.points.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) scene.points.row(j * (n + 1) + i) << 2.0f * i / n - 1, 0, 2.0f * j / n - 1;
  }
  scene.faces.resize(2 * n * n, 3);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      scene.faces.row(2 * (j * n + i)) << a, c, b;
      scene.faces.row(2 * (j * n + i) + 1) << b, c, d;
    }
  }
  scene.camera = make_camera({0.3, 1.6, 2.4}, {0, 0, 0}, {0, 1, 0}, 0.8);
  scene.samples = 1;
  scene.wireframe = true;
  scene.wireframe_colour = Eigen::Vector3f(1, 0, 0);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  int missing = 0, probes = 0;
  for (Eigen::Index f = 0; f < scene.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d a = scene.points.row(scene.faces(f, k)).cast<double>().transpose();
      const Eigen::Vector3d b = scene.points.row(scene.faces(f, (k + 1) % 3)).cast<double>().transpose();
      for (double t = 0.2; t < 0.9; t += 0.3) {
        const Eigen::Vector2d p = camera.project(a + t * (b - a));
        if (p.x() < 1 || p.y() < 1 || p.x() > scene.width - 1 || p.y() > scene.height - 1) continue;  // off the image
        ++probes;
        missing += colour_near(image, static_cast<int>(p.x()), static_cast<int>(p.y()), Rgb{255, 0, 0}) ? 0 : 1;
      }
    }
  }
  EXPECT_GT(probes, 500);
  EXPECT_EQ(missing, 0) << "of " << probes << " points on edges";
}

TEST_F(RenderTest, WireframeDrawsTheEdgesAndNotTheInterior) {
  Scene scene;
  scene.width = 160;
  scene.height = 160;
  scene.points.resize(3, 3);
  scene.points << -1, -0.8f, 0, 1.1f, -0.9f, 0, 0.1f, 1, 0;
  scene.faces.resize(1, 3);
  scene.faces << 0, 1, 2;
  scene.camera = make_camera({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, 0.9);
  scene.samples = 1;
  scene.wireframe = true;
  scene.wireframe_colour = Eigen::Vector3f(1, 0, 0);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const Pinhole camera = pinhole(scene);
  const Rgb red{255, 0, 0};
  for (int edge = 0; edge < 3; ++edge) {
    const Eigen::Vector3d a = scene.points.row(edge).cast<double>().transpose();
    const Eigen::Vector3d b = scene.points.row((edge + 1) % 3).cast<double>().transpose();
    for (double t = 0.1; t < 0.95; t += 0.1) {
      const Eigen::Vector2d p = camera.project(a + t * (b - a));
      EXPECT_TRUE(colour_near(image, static_cast<int>(p.x()), static_cast<int>(p.y()), red))
          << "edge " << edge << " at t = " << t;
    }
  }
  const Eigen::Vector2d centroid = camera.project(scene.points.colwise().mean().cast<double>().transpose());
  const int cx = static_cast<int>(centroid.x()), cy = static_cast<int>(centroid.y());
  EXPECT_FALSE(colour_near(image, cx, cy, red));
  // The interior is the lit surface: the plane faces the eye nearly head-on there.
  EXPECT_GT(rgb(image, cx, cy)[1], 150);
}

TEST_F(RenderTest, PngOfANonSquareRenderKeepsRowOrderAndAspect) {
  // A small sphere in the top-left quadrant of a 320 × 200 image.
  const TriangleMesh mesh = testing::icosphere(3);
  Scene scene;
  scene.width = 320;
  scene.height = 200;
  const Eigen::RowVector3f centre(-1.7f, 1.05f, 0);
  scene.points = (0.3f * mesh.V).rowwise() + centre;
  scene.faces = mesh.F;
  scene.camera = make_camera({0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 0.8);
  scene.background = Eigen::Vector4f(0, 0, 0, 1);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());

  Result<std::string> bytes = encode_png(image);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  Result<Image> decoded = decode_png(*bytes, "thumbnail");
  ASSERT_TRUE(decoded.ok()) << decoded.error().message;
  ASSERT_EQ(decoded->width, 320);
  ASSERT_EQ(decoded->height, 200);
  EXPECT_EQ(decoded->rgba, image.rgba);

  const Eigen::Vector2d expected = pinhole(scene).project(centre.cast<double>().transpose());
  ASSERT_LT(expected.x(), 160);
  ASSERT_LT(expected.y(), 100);
  EXPECT_FALSE(is_background(*decoded, static_cast<int>(expected.x()), static_cast<int>(expected.y())));
  for (int y = 0; y < decoded->height; ++y) {
    for (int x = 0; x < decoded->width; ++x) {
      if (x >= 160 || y >= 100) {
        ASSERT_TRUE(is_background(*decoded, x, y)) << "pixel (" << x << ", " << y << ")";
      }
    }
  }
  // The background alpha is kept.
  EXPECT_EQ(decoded->pixel(300, 190)[3], 255);
}

TEST_F(RenderTest, MultisamplingOnlyChangesTheSilhouette) {
  Scene scene = sphere_scene(200, 150);
  const Image single = render_ok(scene);
  scene.samples = 4;
  const Image multi = render_ok(scene);
  ASSERT_FALSE(single.rgba.empty());
  ASSERT_FALSE(multi.rgba.empty());
  const double radius_px = std::tan(std::asin(0.25)) / pinhole(scene).tan_half * scene.height / 2;
  int blended = 0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const double distance = std::abs(std::hypot(x + 0.5 - 100, y + 0.5 - 75) - radius_px);
      const Rgb a = rgb(single, x, y), b = rgb(multi, x, y);
      if (distance > 1.0) {
        expect_colour_near(b, a, 1, "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
      } else if (a != b) {
        ++blended;
      }
    }
  }
  EXPECT_GT(blended, 50);  // partial coverage along the silhouette
}

TEST_F(RenderTest, BadScenesAreRefusedAndTheRendererKeepsWorking) {
  const Scene good = sphere_scene(96, 64, 3);
  const Image before = render_ok(good);
  ASSERT_FALSE(before.rgba.empty());

  Scene scene = good;
  scene.width = 0;
  Error error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "width: expected ≥ 1, got 0");

  scene = good;
  scene.faces(12, 1) = 900;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "faces: face 12 references vertex 900, the mesh has 642 points");

  scene = good;
  scene.points(5, 1) = std::numeric_limits<float>::quiet_NaN();
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message.rfind("points: point 5 ", 0), 0u) << error.message;

  scene = good;
  scene.samples = 3;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "samples: expected 1, 2, 4 or 8, got 3");

  scene = good;
  scene.key_points = {1, 2, 3, 777};
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "key_points[3]: vertex 777 out of range (642 points)");

  scene = good;
  scene.heat = Eigen::VectorXf::Ones(10);
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "heat: expected 642 values (one per point), got 10");

  scene = good;
  scene.heat = Eigen::VectorXf::Ones(scene.points.rows());
  scene.heat[7] = -1;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message.rfind("heat[7]: ", 0), 0u) << error.message;

  scene = good;
  scene.normals = PointMatrix::Ones(3, 3);
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message.rfind("normals: ", 0), 0u) << error.message;

  scene = good;
  scene.camera->up = Eigen::Vector3d(0, 0, 1);
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "camera.up: parallel to the view direction (target − eye)");

  scene = good;
  scene.points.resize(0, 3);
  scene.faces.resize(0, 3);
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);

  scene = good;
  scene.width = 100000;
  scene.height = 10;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kResourceExhausted);
  EXPECT_EQ(error.message.rfind("width: 100000 exceeds", 0), 0u) << error.message;

  // A valid render at another size in between reallocates the render targets.
  scene = good;
  scene.width = 33;
  scene.samples = 4;
  render_ok(scene);

  const Image after = render_ok(good);
  EXPECT_EQ(after.rgba, before.rgba);
}

TEST_F(RenderTest, AutoFramedMeshIsInsideTheImage) {
  Scene scene = sphere_scene(160, 90, 3);
  scene.camera.reset();
  scene.points = (scene.points * 3).rowwise() + Eigen::RowVector3f(10, -4, 2);
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  // The border is background all round, and the centre is covered.
  for (int x = 0; x < scene.width; ++x) {
    EXPECT_TRUE(is_background(image, x, 0));
    EXPECT_TRUE(is_background(image, x, scene.height - 1));
  }
  for (int y = 0; y < scene.height; ++y) {
    EXPECT_TRUE(is_background(image, 0, y));
    EXPECT_TRUE(is_background(image, scene.width - 1, y));
  }
  EXPECT_FALSE(is_background(image, 80, 45));
}

TEST_F(RenderTest, EverySampleCountRendersOrIsReportedAsExhausted) {
  Scene scene = sphere_scene(64, 64, 2);
  for (const int samples : {1, 2, 4, 8}) {
    scene.samples = samples;
    Result<Image> image = renderer_->render(scene);
    if (image.ok()) {
      EXPECT_FALSE(is_background(*image, 32, 32)) << samples << " samples";
    } else {
      EXPECT_EQ(image.error().code, ErrorCode::kResourceExhausted) << image.error().message;
      EXPECT_EQ(image.error().message.rfind("samples: ", 0), 0u) << image.error().message;
      EXPECT_GT(samples, 1);
    }
  }
}

TEST_F(RenderTest, LargestThumbnailRenders) {
  // 4096² at 4 samples is the server's largest thumbnail.
  Scene scene = sphere_scene(4096, 4096, 4);
  scene.samples = 4;
  Result<Image> image = renderer_->render(scene);
  if (!image.ok()) {
    // Honest failure mode: the implementation's limits, reported as such.
    EXPECT_EQ(image.error().code, ErrorCode::kResourceExhausted) << image.error().message;
    GTEST_SKIP() << "4096 × 4096 at 4 samples refused: " << image.error().message;
  }
  EXPECT_FALSE(is_background(*image, 2048, 2048));
  EXPECT_TRUE(is_background(*image, 0, 0));
  EXPECT_TRUE(is_background(*image, 4095, 4095));
}

TEST_F(RenderTest, AnotherRendererOnTheSameDisplayDoesNotDisturbThisOne) {
  const Scene scene = sphere_scene(64, 48, 2);
  const Image before = render_ok(scene);
  {
    Result<std::unique_ptr<Renderer>> other = make_egl_renderer(test_platform());
    ASSERT_TRUE(other.ok()) << other.error().message;
    Result<Image> image = (*other)->render(scene);
    ASSERT_TRUE(image.ok()) << image.error().message;
    EXPECT_EQ(image->rgba, before.rgba);
  }  // destroyed: the display must stay initialised for renderer_
  EXPECT_EQ(render_ok(scene).rgba, before.rgba);
}

// ---------------------------------------------------------------------------------------------
// The checker texture (Scene::corner_uvs, Checker): a flat grid over [0, 1]² in the plane z = 0,
// seen head-on, whose texture coordinates are known functions of the point. Every pixel whose
// ray (testing::Pinhole) meets the grid well inside one checker square must have that square's
// colour, lit by the documented model at the hit point.

// n × n squares over [0, 1]² at z = 0, two triangles each, counter-clockwise seen from +z.
Scene checker_grid_scene(int n) {
  Scene scene;
  scene.width = 200;
  scene.height = 160;
  scene.points.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) scene.points.row(j * (n + 1) + i) << static_cast<float>(i) / n, static_cast<float>(j) / n, 0;
  }
  scene.faces.resize(2 * n * n, 3);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      scene.faces.row(2 * (j * n + i)) << a, b, d;
      scene.faces.row(2 * (j * n + i) + 1) << a, d, c;
    }
  }
  scene.camera = make_camera({0.5, 0.5, 1.6}, {0.5, 0.5, 0}, {0, 1, 0}, 0.8);
  scene.background = Eigen::Vector4f(0, 0, 0, 1);
  scene.samples = 1;
  scene.shading = Shading::kLambert;
  scene.checker.even = Eigen::Vector3f(0.9f, 0.6f, 0.2f);
  scene.checker.odd = Eigen::Vector3f(0.1f, 0.3f, 0.8f);
  return scene;
}

// Sets each face corner's UV to uv_of(the face's centroid, the corner's point).
template <typename UvOf>
void set_corner_uvs(Scene& scene, UvOf uv_of) {
  scene.corner_uvs.resize(3 * scene.faces.rows(), 2);
  for (Eigen::Index f = 0; f < scene.faces.rows(); ++f) {
    const auto xy = [&](int k) {
      const int32_t v = scene.faces(f, k);
      return Eigen::Vector2d(scene.points(v, 0), scene.points(v, 1));
    };
    const Eigen::Vector2d centroid = (xy(0) + xy(1) + xy(2)) / 3;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d uv = uv_of(centroid, xy(k));
      scene.corner_uvs.row(3 * f + k) << static_cast<float>(uv.x()), static_cast<float>(uv.y());
    }
  }
}

// Compares every pixel whose ray meets the plane z = 0 at (x, y) with `uv_of(x, y)` more than
// `margin` (in UV) inside a checker square, and `inside(x, y)`, with the square's lit colour;
// returns how many pixels it compared.
template <typename UvOf, typename Inside>
int expect_checker_pixels(const Scene& scene, const Image& image, UvOf uv_of, Inside inside, double margin) {
  const Pinhole camera = pinhole(scene);
  const double n = scene.checker.squares_per_uv;
  int compared = 0, wrong = 0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      const Eigen::Vector3d ray = camera.pixel_ray(x, y);
      const double t = -camera.eye.z() / ray.z();
      const Eigen::Vector3d p = camera.eye + t * ray;
      if (!inside(p.x(), p.y())) continue;
      const Eigen::Vector2d uv = uv_of(p.x(), p.y());
      const Eigen::Vector2d s = n * uv;
      const Eigen::Vector2d fraction = s - s.array().floor().matrix();
      if ((fraction.array() < n * margin).any() || (fraction.array() > 1 - n * margin).any()) continue;
      const bool even = static_cast<long>(std::floor(s.x()) + std::floor(s.y())) % 2 == 0;
      Material material = scene.material;
      material.albedo = even ? scene.checker.even : scene.checker.odd;
      const double nl = std::abs((camera.eye - p).normalized().z());  // n = +z
      const Rgb expected = to_rgb8(expected_colour(material, scene.shading, nl));
      const Rgb actual = rgb(image, x, y);
      ++compared;
      bool close = true;
      for (size_t c = 0; c < 3; ++c) close = close && std::abs(actual[c] - expected[c]) <= 2;
      if (!close && ++wrong <= 5) {
        ADD_FAILURE() << "pixel (" << x << ", " << y << ") at uv (" << uv.x() << ", " << uv.y() << "), "
                      << (even ? "even" : "odd") << " square: got " << actual[0] << " " << actual[1] << " "
                      << actual[2] << ", expected " << expected[0] << " " << expected[1] << " " << expected[2];
      }
    }
  }
  EXPECT_EQ(wrong, 0) << "of " << compared << " pixels";
  return compared;
}

TEST_F(RenderTest, CheckerSquaresAreWhereTheTextureCoordinatesPutThem) {
  // UVs an anisotropic affine map of the position: the squares are rectangles in the plane.
  const auto uv_of = [](double x, double y) { return Eigen::Vector2d(0.3 + 0.5 * x, 0.1 + 0.75 * y); };
  for (const float squares : {16.0f, 5.0f}) {
    SCOPED_TRACE("squares_per_uv " + std::to_string(squares));
    Scene scene = checker_grid_scene(4);
    scene.checker.squares_per_uv = squares;
    set_corner_uvs(scene, [&](const Eigen::Vector2d&, const Eigen::Vector2d& p) { return uv_of(p.x(), p.y()); });
    const Image image = render_ok(scene);
    ASSERT_FALSE(image.rgba.empty());
    // 2 pixels of margin: the grid spans about 1.3 units over 200 pixels.
    const double margin = 2 * 1.3 / 200;
    const auto inside = [&](double x, double y) {
      return x > margin && y > margin && x < 1 - margin && y < 1 - margin;
    };
    const int compared = expect_checker_pixels(scene, image, uv_of, inside, margin * 0.75);
    EXPECT_GT(compared, 5000);
  }
}

TEST_F(RenderTest, CheckerFollowsEachCornersOwnTextureCoordinateAcrossASeam) {
  // Two charts: the faces left of x = 1/2 map to (x, y), those right of it to (x + ½ square, y),
  // so the vertices on x = 1/2 have a different UV in each chart. Drawn with one UV per vertex,
  // the right chart would be off by half a square.
  Scene scene = checker_grid_scene(4);
  scene.checker.squares_per_uv = 8;
  const double shift = 0.5 / 8;
  set_corner_uvs(scene, [&](const Eigen::Vector2d& centroid, const Eigen::Vector2d& p) {
    return Eigen::Vector2d(p.x() + (centroid.x() > 0.5 ? shift : 0.0), p.y());
  });
  const Image image = render_ok(scene);
  ASSERT_FALSE(image.rgba.empty());
  const double margin = 2 * 1.3 / 200;
  const auto uv_of = [&](double x, double y) { return Eigen::Vector2d(x + (x > 0.5 ? shift : 0.0), y); };
  const auto inside = [&](double x, double y) {
    return x > margin && y > margin && x < 1 - margin && y < 1 - margin && std::abs(x - 0.5) > margin;
  };
  EXPECT_GT(expect_checker_pixels(scene, image, uv_of, inside, margin * 0.75), 5000);
}

TEST_F(RenderTest, ChartBordersAreDrawnOnSeamsAndNowhereElse) {
  Scene scene = checker_grid_scene(4);
  scene.checker.squares_per_uv = 8;
  scene.checker.chart_border_colour = Eigen::Vector3f(1, 0, 1);
  set_corner_uvs(scene, [&](const Eigen::Vector2d& centroid, const Eigen::Vector2d& p) {
    return Eigen::Vector2d(p.x() + (centroid.x() > 0.5 ? 0.3 : 0.0), p.y());
  });
  const Pinhole camera = pinhole(scene);
  const Rgb magenta{255, 0, 255};
  const auto on_line = [&](const Image& image, double x0, double y0, double x1, double y1) {
    int hits = 0, probes = 0;
    for (double t = 0.1; t < 0.95; t += 0.05) {
      const Eigen::Vector2d q = camera.project({x0 + t * (x1 - x0), y0 + t * (y1 - y0), 0});
      ++probes;
      hits += colour_near(image, static_cast<int>(q.x()), static_cast<int>(q.y()), magenta) ? 1 : 0;
    }
    return std::pair(hits, probes);
  };
  for (const bool borders : {false, true}) {
    SCOPED_TRACE(borders ? "borders" : "no borders");
    scene.checker.chart_borders = borders;
    const Image image = render_ok(scene);
    ASSERT_FALSE(image.rgba.empty());
    // The seam x = 1/2 and the mesh's boundary are chart borders; the grid lines x = 1/4 and
    // y = 1/2 inside the left chart and its diagonals are not.
    for (const auto& [x0, y0, x1, y1] : std::vector<std::array<double, 4>>{
             {0.5, 0, 0.5, 1}, {0, 0, 1, 0}, {0, 1, 1, 1}, {0, 0, 0, 1}, {1, 0, 1, 1}}) {
      const auto [hits, probes] = on_line(image, x0, y0, x1, y1);
      EXPECT_EQ(hits, borders ? probes : 0) << "(" << x0 << ", " << y0 << ") to (" << x1 << ", " << y1 << ")";
    }
    for (const auto& [x0, y0, x1, y1] : std::vector<std::array<double, 4>>{{0.25, 0, 0.25, 1}, {0, 0.5, 0.45, 0.5}, {0, 0, 0.5, 0.5}}) {
      EXPECT_EQ(on_line(image, x0, y0, x1, y1).first, 0)
          << "(" << x0 << ", " << y0 << ") to (" << x1 << ", " << y1 << ")";
    }
  }
}

TEST_F(RenderTest, BadCheckersAreRefusedNamingTheField) {
  Scene good = checker_grid_scene(2);
  set_corner_uvs(good, [](const Eigen::Vector2d&, const Eigen::Vector2d& p) { return p; });
  ASSERT_FALSE(render_ok(good).rgba.empty());

  Scene scene = good;
  scene.corner_uvs.conservativeResize(5, 2);
  Error error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "corner_uvs: expected 24 rows (3 per face) or none, got 5");

  scene = good;
  scene.corner_uvs(7, 1) = std::numeric_limits<float>::infinity();
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message.rfind("corner_uvs: corner 1 of face 2 is not finite", 0), 0u) << error.message;

  for (const float squares : {0.0f, -2.0f, std::numeric_limits<float>::quiet_NaN()}) {
    scene = good;
    scene.checker.squares_per_uv = squares;
    error = render_error(scene);
    EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
    EXPECT_EQ(error.message.rfind("checker.squares_per_uv: expected a finite value > 0, got ", 0), 0u) << error.message;
  }

  scene = good;
  scene.heat = Eigen::VectorXf::Zero(scene.points.rows());
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "corner_uvs: set together with heat; the surface takes its colour from one of them");

  scene = good;
  scene.corner_uvs.resize(0, 2);
  scene.checker.chart_borders = true;
  error = render_error(scene);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message.rfind("checker.chart_borders: needs corner_uvs", 0), 0u) << error.message;

  EXPECT_FALSE(render_ok(good).rgba.empty());
}

TEST(RenderPlatformTest, NamesRoundTrip) {
  for (const EglPlatform platform : {EglPlatform::kAuto, EglPlatform::kSurfaceless, EglPlatform::kDevice}) {
    Result<EglPlatform> parsed = parse_egl_platform(egl_platform_name(platform));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, platform);
  }
  Result<EglPlatform> bad = parse_egl_platform("gpu");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
}

TEST(RenderPlatformTest, DeviceAndAutoOpenOrSayWhy) {
  // Without a GPU the device platform has only Mesa's software device, which it skips; auto then
  // falls back to surfaceless.
  Result<std::unique_ptr<Renderer>> device = make_egl_renderer(EglPlatform::kDevice);
  if (device.ok()) {
    EXPECT_EQ((*device)->description().rfind("EGL device — ", 0), 0u) << (*device)->description();
  } else {
    EXPECT_EQ(device.error().code, ErrorCode::kFailedPrecondition);
    EXPECT_EQ(device.error().message.rfind("EGL device: ", 0), 0u) << device.error().message;
  }
  Result<std::unique_ptr<Renderer>> automatic = make_egl_renderer(EglPlatform::kAuto);
  if (!automatic.ok()) {
    EXPECT_EQ(automatic.error().code, ErrorCode::kFailedPrecondition);
    GTEST_SKIP() << automatic.error().message;
  }
  EXPECT_EQ((*automatic)->description().find(device.ok() ? "EGL device" : "EGL surfaceless"), 0u)
      << (*automatic)->description();
}

}  // namespace
}  // namespace animspace::render
