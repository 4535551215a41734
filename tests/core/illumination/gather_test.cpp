#include "core/illumination/gather.h"
#include "core/illumination/gather_noise.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace animspace::illumination {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Appends the rectangle corner + a·u + b·v (a, b ∈ [0, 1]) as an nu × nv grid with its own
// vertices, lit on the side of `normal`, triangles counter-clockwise seen from that side. When
// `weights` is given, appends each vertex's trapezoid-rule area weight.
void add_rectangle(SurfaceMesh& mesh, const Eigen::Vector3d& corner, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
                   int nu, int nv, const Eigen::Vector3d& normal, const Eigen::Vector3d& rho,
                   std::vector<double>* weights = nullptr) {
  const Eigen::Index first = mesh.vertices.rows();
  const Eigen::Index count = static_cast<Eigen::Index>(nu + 1) * (nv + 1);
  mesh.vertices.conservativeResize(first + count, 3);
  mesh.normals.conservativeResize(first + count, 3);
  mesh.albedo.conservativeResize(first + count, 3);
  const double cell_area = u.norm() * v.norm() / (nu * nv);
  for (int j = 0; j <= nv; ++j) {
    for (int i = 0; i <= nu; ++i) {
      const Eigen::Index row = first + j * (nu + 1) + i;
      mesh.vertices.row(row) = (corner + (static_cast<double>(i) / nu) * u + (static_cast<double>(j) / nv) * v).cast<float>();
      mesh.normals.row(row) = normal.cast<float>();
      mesh.albedo.row(row) = rho.cast<float>();
      if (weights != nullptr) {
        weights->push_back(cell_area * ((i == 0 || i == nu) ? 0.5 : 1.0) * ((j == 0 || j == nv) ? 0.5 : 1.0));
      }
    }
  }
  const bool ccw = u.cross(v).dot(normal) > 0;
  const Eigen::Index first_face = mesh.faces.rows();
  mesh.faces.conservativeResize(first_face + 2 * nu * nv, 3);
  Eigen::Index f = first_face;
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      const auto a = static_cast<int32_t>(first + j * (nu + 1) + i);
      const int32_t b = a + 1, c = a + nu + 2, d = a + nu + 1;
      if (ccw) {
        mesh.faces.row(f++) << a, b, c;
        mesh.faces.row(f++) << a, c, d;
      } else {
        mesh.faces.row(f++) << a, c, b;
        mesh.faces.row(f++) << a, d, c;
      }
    }
  }
}

std::unique_ptr<IlluminationEngine> make_engine(SurfaceMesh mesh) {
  auto engine = IlluminationEngine::create(std::move(mesh));
  EXPECT_TRUE(engine.ok()) << (engine.ok() ? "" : engine.error().message);
  return std::move(engine).value();
}

std::vector<int> range(int begin, int end) {
  std::vector<int> points;
  for (int i = begin; i < end; ++i) points.push_back(i);
  return points;
}

// ---- Direct ------------------------------------------------------------------------------------

TEST(IlluminationDirect, MatchesThePointLightFormulaAndShadows) {
  const Eigen::Vector3d rho(0.5, 0.3, 0.2);
  SurfaceMesh mesh;
  add_rectangle(mesh, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, 10, 10, {0, 1, 0}, rho);  // floor: 121 vertices
  const int floor_vertices = 121;
  // A blocker at y = 0.4 over x ∈ [−0.3, 0.1], z ∈ [−0.5, −0.1].
  add_rectangle(mesh, {-0.3, 0.4, -0.5}, {0.4, 0, 0}, {0, 0, 0.4}, 2, 2, {0, 1, 0}, rho);
  auto engine = make_engine(mesh);
  const PointLight light{{0.2, 0.8, -0.1}, {2, 3, 4}};
  Eigen::VectorXf out;
  engine->direct({light}, range(0, floor_vertices), out);
  ASSERT_EQ(out.size(), 3 * floor_vertices);
  int lit = 0, shadowed = 0;
  for (int v = 0; v < floor_vertices; ++v) {
    const Eigen::Vector3d x = mesh.vertices.row(v).cast<double>();
    const Eigen::Vector3d to_light = light.position - x;
    // Where the segment to the light crosses the blocker's plane (half way up).
    const Eigen::Vector3d crossing = x + (0.4 / to_light.y()) * to_light;
    const double outside = std::max({-0.3 - crossing.x(), crossing.x() - 0.1, -0.5 - crossing.z(), crossing.z() + 0.1});
    if (std::abs(outside) < 1e-3) continue;  // grazing the blocker's edge
    const double r = to_light.norm();
    const Eigen::Vector3d expected =
        outside > 0 ? Eigen::Vector3d(rho.cwiseProduct(light.intensity) / kPi * to_light.y() / (r * r * r))
                    : Eigen::Vector3d::Zero();
    ++(outside > 0 ? lit : shadowed);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(out[3 * v + k], expected[k], 1e-6 * expected[k]) << "vertex " << v << " channel " << k;
    }
  }
  EXPECT_GT(lit, 60);
  EXPECT_GT(shadowed, 3);

  // A light below the floor lights nothing (the floor's lit side faces up).
  engine->direct({{{0.2, -0.5, 0.0}, {1, 1, 1}}}, range(0, floor_vertices), out);
  EXPECT_TRUE(out.isZero(0));
}

// Issue #38: with cell_shadow_rays the direct light stored at a vertex is the point light's value
// at the vertex times the fraction of its cell — the part of its triangles where its barycentric
// weight is the largest — that sees the light. The floor's 0.2 m cells under a square blocker
// 0.4 m up: the fraction of each cell is counted on 400² floor points (which triangle, which
// corner weighs most, and whether the segment to the light crosses the blocker), independently
// of the engine. 64 rays per cell: within 1/16, the standard error 64 independent rays would have
// in a half-lit cell (the low-discrepancy rays do better). Every cell the edge crosses must be
// found (a partly lit cell left at 0 or 1 is off by its whole fraction), and a cell that sees the
// light whole, or not at all, keeps direct()'s value bit for bit.
TEST(IlluminationDirect, TheStoredDirectLightIsTheMeanOverTheVertexsCell) {
  const Eigen::Vector3d rho(0.5, 0.3, 0.2);
  constexpr int kCells = 10;
  constexpr double kSide = 2.0, kCell = kSide / kCells;
  SurfaceMesh mesh;
  // Floor x ∈ [−1, 1], z ∈ [−1, 1]: vertex (i, j) at (−1 + i·cell, 0, 1 − j·cell).
  add_rectangle(mesh, {-1, 0, 1}, {kSide, 0, 0}, {0, 0, -kSide}, kCells, kCells, {0, 1, 0}, rho);
  constexpr int kFloor = (kCells + 1) * (kCells + 1);
  const double blocker_y = 0.4, x0 = -0.37, x1 = 0.21, z0 = -0.43, z1 = 0.12;
  add_rectangle(mesh, {x0, blocker_y, z0}, {x1 - x0, 0, 0}, {0, 0, z1 - z0}, 2, 2, {0, 1, 0}, rho);
  auto engine = make_engine(mesh);
  const PointLight light{{0.13, 0.9, -0.05}, {2, 3, 4}};
  const auto shadowed = [&](const Eigen::Vector3d& y) {
    const Eigen::Vector3d crossing = y + (blocker_y / light.position.y()) * (light.position - y);
    return crossing.x() > x0 && crossing.x() < x1 && crossing.z() > z0 && crossing.z() < z1;
  };
  std::vector<double> lit(kFloor, 0), total(kFloor, 0);
  constexpr int kFine = 400;
  for (int b = 0; b < kFine; ++b) {
    for (int a = 0; a < kFine; ++a) {
      const double fi = (a + 0.5) / kFine * kCells, fj = (b + 0.5) / kFine * kCells;  // grid coordinates
      const int i = static_cast<int>(fi), j = static_cast<int>(fj);
      const double s = fi - i, t = fj - j;
      // add_rectangle's triangles: (i, j), (i + 1, j), (i + 1, j + 1) where s ≥ t, else
      // (i, j), (i + 1, j + 1), (i, j + 1); the corner with the largest barycentric owns the point.
      const int v00 = j * (kCells + 1) + i, v10 = v00 + 1, v11 = v00 + kCells + 2, v01 = v00 + kCells + 1;
      std::vector<std::pair<double, int>> corners =
          s >= t ? std::vector<std::pair<double, int>>{{1 - s, v00}, {s - t, v10}, {t, v11}}
                 : std::vector<std::pair<double, int>>{{1 - t, v00}, {s, v11}, {t - s, v01}};
      const int owner = std::max_element(corners.begin(), corners.end())->second;
      total[static_cast<size_t>(owner)] += 1;
      lit[static_cast<size_t>(owner)] += shadowed({-1 + fi * kCell, 0, 1 - fj * kCell}) ? 0 : 1;
    }
  }
  GatherOptions options{1, 3};
  options.direct_from_vertices = true;
  options.cell_shadow_rays = 64;
  Eigen::VectorXf stored, at_vertex, point_values;
  engine->vertex_direct({light}, options, stored);
  engine->direct({light}, engine->all_points(), at_vertex);
  options.cell_shadow_rays = 0;
  engine->vertex_direct({light}, options, point_values);
  ASSERT_EQ(stored.size(), 3 * engine->point_count());
  for (Eigen::Index i = 0; i < at_vertex.size(); ++i) ASSERT_EQ(point_values[i], at_vertex[i]) << "without cell rays, value " << i;
  int partial = 0, whole = 0;
  double largest_error = 0, largest_point_error = 0;
  for (int v = 0; v < kFloor; ++v) {
    const Eigen::Vector3d x = mesh.vertices.row(v).cast<double>();
    const Eigen::Vector3d to_light = light.position - x;
    const double r = to_light.norm();
    const Eigen::Vector3d unshadowed = rho.cwiseProduct(light.intensity) / kPi * to_light.y() / (r * r * r);
    const double fraction = lit[static_cast<size_t>(v)] / total[static_cast<size_t>(v)];
    for (int k = 0; k < 3; ++k) {
      largest_error = std::max(largest_error, std::abs(stored[3 * v + k] / unshadowed[k] - fraction));
      largest_point_error = std::max(largest_point_error, std::abs(at_vertex[3 * v + k] / unshadowed[k] - fraction));
    }
    if (fraction > 0.05 && fraction < 0.95) ++partial;
    if (fraction == 0 || fraction == 1) {
      ++whole;
      for (int k = 0; k < 3; ++k) EXPECT_EQ(stored[3 * v + k], at_vertex[3 * v + k]) << "vertex " << v << " channel " << k;
    }
  }
  EXPECT_LT(largest_error, 1.0 / 16);
  EXPECT_GE(partial, 10);  // the shadow's edges cross that many cells
  EXPECT_GT(whole, 60);
  EXPECT_GT(largest_point_error, 0.3);  // the vertex's own shadow ray is far from its cell's mean
}

// ---- Indirect: closed forms and quadratures --------------------------------------------------

// One bounce between parallel planes: a point light at height h over a lit floor square
// [−L, L]² (y = 0, albedo ρ_f), seen from a ceiling point x at height H (albedo ρ_c) looking down:
//   L_i(x) = ρ_c/π ∫ L_d(y) cos θ_x cos θ_y / r² dA,   L_d(y) = ρ_f/π · I h / d(y)³,
// with cos θ_x = cos θ_y = H / r. The gather's estimator f = ρ_c L_d(y(ω)) under the cosine pdf
// has mean L_i and second moment ρ_c²/π ∫ L_d² cos θ_x cos θ_y / r² dA, which bound its standard
// error (for independent samples; the rotated Hammersley set does better).
struct PlaneMoments {
  double mean = 0;           // per unit ρ_c ρ_f I
  double second_moment = 0;  // per unit (ρ_c ρ_f I)²
};

// L_d / (ρ_f I) at a floor point y.
double floor_direct(const Eigen::Vector3d& y, const Eigen::Vector3d& light) {
  const double d = (light - y).norm();
  return light.y() / (kPi * d * d * d);
}

// The moments of the estimator whose hits read psi_at(y) for L_d / (ρ_f I) (floor_moments: the
// exact field, floor_direct).
template <typename Psi>
PlaneMoments floor_moments_of(const Eigen::Vector3d& x, double half_side, Psi psi_at, int cells = 1200) {
  const double step = 2 * half_side / cells;
  const double H = x.y();
  double m1 = 0, m2 = 0;
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      const Eigen::Vector3d y(-half_side + (i + 0.5) * step, 0.0, -half_side + (j + 0.5) * step);
      const double r2 = (x - y).squaredNorm();
      const double psi = psi_at(y);
      const double kernel = H * H / (r2 * r2) / kPi;  // cos θ_x cos θ_y / (π r²)
      m1 += psi * kernel;
      m2 += psi * psi * kernel;
    }
  }
  return {m1 * step * step, m2 * step * step};
}

PlaneMoments floor_moments(const Eigen::Vector3d& x, const Eigen::Vector3d& light, double half_side) {
  return floor_moments_of(x, half_side, [&](const Eigen::Vector3d& y) { return floor_direct(y, light); });
}

struct ParallelPlanes {
  static constexpr double kHalfSide = 2.0;
  static constexpr double kCeiling = 1.0;
  const Eigen::Vector3d rho_floor{0.6, 0.5, 0.4};
  const Eigen::Vector3d rho_ceiling{0.7, 0.3, 0.5};
  static constexpr int kCeilingCells = 4;  // per side of the ceiling's 1 m square
  const PointLight light;
  const double ceiling;  // its height
  SurfaceMesh mesh;
  int ceiling_first = 0;
  int ceiling_count = 0;

  explicit ParallelPlanes(const PointLight& light_below = {{0.1, 0.5, -0.2}, {3, 2, 1}}, double height = kCeiling)
      : light(light_below), ceiling(height) {
    add_rectangle(mesh, {-kHalfSide, 0, kHalfSide}, {2 * kHalfSide, 0, 0}, {0, 0, -2 * kHalfSide}, 8, 8, {0, 1, 0},
                  rho_floor);
    ceiling_first = static_cast<int>(mesh.vertices.rows());
    // Vertex (i, j) at x = −0.5 + i / 4, z = −0.5 + j / 4 is ceiling point j·5 + i.
    add_rectangle(mesh, {-0.5, ceiling, -0.5}, {1, 0, 0}, {0, 0, 1}, kCeilingCells, kCeilingCells, {0, -1, 0},
                  rho_ceiling);
    ceiling_count = static_cast<int>(mesh.vertices.rows()) - ceiling_first;
  }
};

// Per-seed estimates at the parallel planes' ceiling points against the moments of their
// estimator (`moments_at(x)`, per unit ρ_c ρ_f I): each estimate within 4 independent-sample
// standard errors, the seeds' spread non-zero (they do rotate the directions), and their mean
// within 4 standard errors of the mean plus the ray origins' offset. The origins sit ~1e-4 × the
// scene's size (here ~6e-4 m) below the ceiling, which moves the value by ~2·6e-4 / H; hence the
// 2e-3 relative allowance (for H = 1 m) besides the statistical one.
template <typename MomentsAt>
void expect_seeds_match_quadrature(const ParallelPlanes& scene, const std::vector<int>& ceiling,
                                   const std::vector<Eigen::VectorXf>& estimates, int samples, MomentsAt moments_at,
                                   double offset_allowance = 2e-3) {
  const auto seeds = static_cast<double>(estimates.size());
  for (int p = 0; p < scene.ceiling_count; ++p) {
    const Eigen::Vector3d x = scene.mesh.vertices.row(ceiling[static_cast<size_t>(p)]).cast<double>();
    const PlaneMoments m = moments_at(x);
    for (int k = 0; k < 3; ++k) {
      const double scale = scene.rho_ceiling[k] * scene.rho_floor[k] * scene.light.intensity[k];
      const double exact = scale * m.mean;
      // Independent samples would have this standard error; one rotated point set is no worse.
      const double iid_sigma = scale * std::sqrt((m.second_moment - m.mean * m.mean) / samples);
      double sum = 0, sum2 = 0;
      for (const Eigen::VectorXf& estimate : estimates) {
        const double value = estimate[3 * p + k];
        EXPECT_NEAR(value, exact, 4 * iid_sigma) << "ceiling vertex " << p << " channel " << k;
        sum += value;
        sum2 += value * value;
      }
      const double mean = sum / seeds;
      const double spread = std::sqrt(std::max(0.0, (sum2 - seeds * mean * mean) / (seeds - 1)));
      EXPECT_GT(spread, 0.0);
      EXPECT_NEAR(mean, exact, 4 * spread / std::sqrt(seeds) + offset_allowance * exact)
          << "ceiling vertex " << p << " channel " << k;
    }
  }
}

TEST(IlluminationIndirect, ParallelPlanesMatchQuadratureWithinStandardError) {
  const ParallelPlanes scene;
  auto engine = make_engine(scene.mesh);
  // Each seed rotates the point set independently, so the estimates of one point over seeds are
  // independent and unbiased: their spread gives the standard error of their mean.
  const int samples = 256, seeds = 16;
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  std::vector<Eigen::VectorXf> estimates(seeds);
  for (int seed = 0; seed < seeds; ++seed) {
    engine->indirect({scene.light}, {samples, static_cast<uint64_t>(seed)}, ceiling, estimates[static_cast<size_t>(seed)]);
  }
  expect_seeds_match_quadrature(scene, ceiling, estimates, samples, [&](const Eigen::Vector3d& x) {
    return floor_moments(x, scene.light.position, ParallelPlanes::kHalfSide);
  });
}

// Issue #38: jittered strata (one jitter per cell from (seed, point, cell)) are unbiased — the mean
// over independent seeds matches the quadrature of the parallel planes — and, like any
// stratification, no noisier per seed than independent samples. S = 50 has uneven rows (7 rows
// of 7 or 8 cells).
TEST(IlluminationIndirect, StratifiedSamplingIsUnbiasedOnParallelPlanes) {
  const ParallelPlanes scene;
  auto engine = make_engine(scene.mesh);
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  for (const int samples : {64, 50}) {
    SCOPED_TRACE("samples " + std::to_string(samples));
    const int seeds = 24;
    std::vector<Eigen::VectorXf> estimates(seeds);
    for (int seed = 0; seed < seeds; ++seed) {
      GatherOptions options;
      options.samples = samples;
      options.seed = static_cast<uint64_t>(seed);
      options.sampling = HemisphereSampling::kStratified;
      engine->indirect({scene.light}, options, ceiling, estimates[static_cast<size_t>(seed)]);
    }
    expect_seeds_match_quadrature(scene, ceiling, estimates, samples, [&](const Eigen::Vector3d& x) {
      return floor_moments(x, scene.light.position, ParallelPlanes::kHalfSide);
    });
  }
}

// Issue #38: with direct_from_vertices a hit reads L_d interpolated linearly over its triangle
// from the triangle's vertices. On the parallel planes' coarse floor (8 × 8 cells of 0.5 m under a
// light 0.5 m high, each cell cut along its diagonal from vertex (i, j) to (i + 1, j + 1)) that
// interpolant is far from L_d, so the gather's mean over seeds must match the quadrature of the
// interpolant, computed here from the grid — and not the exact field's.
TEST(IlluminationIndirect, DirectFromVerticesIntegratesTheInterpolantOfTheVertexValues) {
  const ParallelPlanes scene;
  auto engine = make_engine(scene.mesh);
  constexpr int kCells = 8;
  const double cell = 2 * ParallelPlanes::kHalfSide / kCells;
  // Floor vertex (i, j) sits at x = −L + i·cell, z = L − j·cell (add_rectangle's u and v).
  const auto vertex_value = [&](int i, int j) {
    return floor_direct({-ParallelPlanes::kHalfSide + i * cell, 0.0, ParallelPlanes::kHalfSide - j * cell},
                        scene.light.position);
  };
  const auto interpolant = [&](const Eigen::Vector3d& y) {
    const double fi = (y.x() + ParallelPlanes::kHalfSide) / cell;
    const double fj = (ParallelPlanes::kHalfSide - y.z()) / cell;
    const int i = std::clamp(static_cast<int>(std::floor(fi)), 0, kCells - 1);
    const int j = std::clamp(static_cast<int>(std::floor(fj)), 0, kCells - 1);
    const double s = fi - i, t = fj - j;
    const double a = vertex_value(i, j), b = vertex_value(i + 1, j), c = vertex_value(i + 1, j + 1),
                 d = vertex_value(i, j + 1);
    // Triangle (a, b, c) where s ≥ t, (a, c, d) where t ≥ s.
    return s >= t ? a + s * (b - a) + t * (c - b) : a + s * (c - d) + t * (d - a);
  };
  const int samples = 256, seeds = 16;
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  std::vector<Eigen::VectorXf> estimates(seeds);
  for (int seed = 0; seed < seeds; ++seed) {
    GatherOptions options{samples, static_cast<uint64_t>(seed)};
    options.direct_from_vertices = true;
    engine->indirect({scene.light}, options, ceiling, estimates[static_cast<size_t>(seed)]);
  }
  expect_seeds_match_quadrature(scene, ceiling, estimates, samples, [&](const Eigen::Vector3d& x) {
    return floor_moments_of(x, ParallelPlanes::kHalfSide, interpolant);
  });
  double largest_gap = 0;  // between the exact field's and the interpolant's means, ÷ the interpolant's
  for (int p = 0; p < scene.ceiling_count; ++p) {
    const Eigen::Vector3d x = scene.mesh.vertices.row(ceiling[static_cast<size_t>(p)]).cast<double>();
    const double interpolated = floor_moments_of(x, ParallelPlanes::kHalfSide, interpolant).mean;
    const double exact = floor_moments(x, scene.light.position, ParallelPlanes::kHalfSide).mean;
    largest_gap = std::max(largest_gap, std::abs(exact - interpolated) / interpolated);
  }
  // The test tells the two apart: the coarse interpolant is well outside the allowance above.
  EXPECT_GT(largest_gap, 0.05);
}


// Issue #38: with cell_average a vertex's rays leave from uniform points of its cell, the part of
// its triangles where its barycentric weight is the largest, so its value is the mean over the
// cell of the point values. The ceiling 0.25 m over a light 0.1 m above the floor sees a bump of
// indirect light about as wide as its cells (0.25 m): the expected value of each ceiling vertex is
// the mean of the quadrature's point moments over its cell — the point moments on a 33 × 33 grid,
// bilinear between, averaged over the 256² midpoints of the ceiling that the vertex's barycentric
// weight wins — and the vertex's own point value is far from it. Origins 0.57 mm below the
// ceiling (1e-4 × the scene's size) move the value by ~2·0.57 / 250: the allowance is 1%.
TEST(IlluminationIndirect, CellAverageIsTheMeanOfThePointValuesOverTheVertexsCell) {
  const ParallelPlanes scene({{0.1, 0.1, -0.2}, {3, 2, 1}}, 0.25);
  auto engine = make_engine(scene.mesh);
  constexpr int kCells = ParallelPlanes::kCeilingCells, kGrid = 32, kFine = 256;
  constexpr int kSide = kCells + 1;  // vertices per side of the ceiling
  const auto point_moments = [&](double x, double z) {
    return floor_moments_of({x, scene.ceiling, z}, ParallelPlanes::kHalfSide,
                            [&](const Eigen::Vector3d& y) { return floor_direct(y, scene.light.position); }, 400);
  };
  std::vector<PlaneMoments> grid(static_cast<size_t>((kGrid + 1) * (kGrid + 1)));
  for (int j = 0; j <= kGrid; ++j) {
    for (int i = 0; i <= kGrid; ++i) {
      grid[static_cast<size_t>(j * (kGrid + 1) + i)] =
          point_moments(-0.5 + static_cast<double>(i) / kGrid, -0.5 + static_cast<double>(j) / kGrid);
    }
  }
  std::vector<PlaneMoments> cell(kSide * kSide);
  std::vector<int> count(kSide * kSide, 0);
  for (int b = 0; b < kFine; ++b) {
    for (int a = 0; a < kFine; ++a) {
      const double u = (a + 0.5) / kFine, w = (b + 0.5) / kFine;  // in the ceiling's square
      // The point moments there, bilinear in the grid.
      const double gu = u * kGrid, gw = w * kGrid;
      const int gi = static_cast<int>(gu), gj = static_cast<int>(gw);
      const double fu = gu - gi, fw = gw - gj;
      PlaneMoments m;
      for (const auto& [di, dj, weight] : {std::tuple{0, 0, (1 - fu) * (1 - fw)}, std::tuple{1, 0, fu * (1 - fw)},
                                           std::tuple{0, 1, (1 - fu) * fw}, std::tuple{1, 1, fu * fw}}) {
        const PlaneMoments& g = grid[static_cast<size_t>((gj + dj) * (kGrid + 1) + gi + di)];
        m.mean += weight * g.mean;
        m.second_moment += weight * g.second_moment;
      }
      // Its triangle (cell (i, j) cut from (i, j) to (i + 1, j + 1)) and the vertex whose
      // barycentric weight is the largest.
      const double cu = u * kCells, cw = w * kCells;
      const int i = static_cast<int>(cu), j = static_cast<int>(cw);
      const double s = cu - i, t = cw - j;
      std::vector<std::pair<double, int>> corners;
      if (s >= t) {
        corners = {{1 - s, j * kSide + i}, {s - t, j * kSide + i + 1}, {t, (j + 1) * kSide + i + 1}};
      } else {
        corners = {{1 - t, j * kSide + i}, {s, (j + 1) * kSide + i + 1}, {t - s, (j + 1) * kSide + i}};
      }
      const int v = std::max_element(corners.begin(), corners.end())->second;
      cell[static_cast<size_t>(v)].mean += m.mean;
      cell[static_cast<size_t>(v)].second_moment += m.second_moment;
      ++count[static_cast<size_t>(v)];
    }
  }
  for (int v = 0; v < kSide * kSide; ++v) {
    ASSERT_GT(count[static_cast<size_t>(v)], 0);
    cell[static_cast<size_t>(v)].mean /= count[static_cast<size_t>(v)];
    cell[static_cast<size_t>(v)].second_moment /= count[static_cast<size_t>(v)];
  }
  const auto vertex_of = [&](const Eigen::Vector3d& x) {
    return static_cast<int>(std::lround((x.z() + 0.5) * kCells)) * kSide +
           static_cast<int>(std::lround((x.x() + 0.5) * kCells));
  };

  const int samples = 256, seeds = 16;
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  std::vector<Eigen::VectorXf> estimates(seeds);
  for (int seed = 0; seed < seeds; ++seed) {
    GatherOptions options{samples, static_cast<uint64_t>(seed)};
    options.cell_average = true;
    engine->indirect({scene.light}, options, ceiling, estimates[static_cast<size_t>(seed)]);
  }
  expect_seeds_match_quadrature(
      scene, ceiling, estimates, samples,
      [&](const Eigen::Vector3d& x) { return cell[static_cast<size_t>(vertex_of(x))]; }, 1e-2);
  // The test tells a cell's mean from its vertex's value.
  double largest_gap = 0;
  for (int p = 0; p < scene.ceiling_count; ++p) {
    const Eigen::Vector3d x = scene.mesh.vertices.row(ceiling[static_cast<size_t>(p)]).cast<double>();
    const double mean = cell[static_cast<size_t>(vertex_of(x))].mean;
    largest_gap = std::max(largest_gap, std::abs(point_moments(x.x(), x.z()).mean - mean) / mean);
  }
  EXPECT_GT(largest_gap, 0.1);
}

// With nothing between the hits and the light, every shadow ray to the light's disc arrives: a
// light of any radius gives the point light's value (the irradiance uses the centre).
TEST(IlluminationIndirect, AnUnoccludedDiscLightEqualsThePointLight) {
  const ParallelPlanes scene;  // the light 0.5 m above the floor, the ceiling 0.5 m above it
  auto engine = make_engine(scene.mesh);
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  GatherOptions point;
  point.samples = 64;
  Eigen::VectorXf expected, disc;
  engine->indirect({scene.light}, point, ceiling, expected);
  ASSERT_GT(expected.minCoeff(), 0.0f);
  for (const int rays : {1, 3, 8}) {
    GatherOptions options = point;
    options.light_radius = 0.05;
    options.shadow_rays = rays;
    engine->indirect({scene.light}, options, ceiling, disc);
    for (Eigen::Index i = 0; i < expected.size(); ++i) {
      EXPECT_NEAR(disc[i], expected[i], 1e-6 * expected[i]) << "shadow rays " << rays << " value " << i;
    }
  }
}

// A disc light partly hidden by a blocker whose edge lies right below the light's centre: each
// hit's visibility is a fraction in [0, 1], so the gathered value lies between 0 and the same
// gather with the blocker taken away (the ceiling's rays that meet the blocker meet its unlit
// top and add nothing either way); and the disc's soft shadow differs from the point's hard one.
TEST(IlluminationIndirect, APartlyHiddenDiscLightIsBetweenDarkAndUnblocked) {
  ParallelPlanes scene;
  // A blocker between the floor and the light, lit side down, over x ∈ [−2, 0.1].
  add_rectangle(scene.mesh, {-2, 0.25, -2}, {2.1, 0, 0}, {0, 0, 4}, 4, 4, {0, -1, 0}, {0.0, 0.0, 0.0});
  auto engine = make_engine(scene.mesh);
  const std::vector<int> ceiling = range(scene.ceiling_first, scene.ceiling_first + scene.ceiling_count);
  const ParallelPlanes open;
  auto open_engine = make_engine(open.mesh);
  GatherOptions options;
  options.samples = 64;
  options.light_radius = 0.05;
  options.shadow_rays = 4;
  Eigen::VectorXf hidden, unblocked, point;
  engine->indirect({scene.light}, options, ceiling, hidden);
  open_engine->indirect({scene.light}, options, ceiling, unblocked);
  GatherOptions point_options = options;
  point_options.light_radius = 0;
  engine->indirect({scene.light}, point_options, ceiling, point);
  for (Eigen::Index i = 0; i < hidden.size(); ++i) {
    EXPECT_GE(hidden[i], 0.0f);
    EXPECT_LE(hidden[i], unblocked[i] * (1 + 1e-6f)) << i;
  }
  // The blocker does hide part of the floor's light, and the disc's penumbra differs from the
  // point light's hard shadow somewhere.
  EXPECT_LT(hidden.sum(), 0.99f * unblocked.sum());
  EXPECT_GT((hidden - point).cwiseAbs().maxCoeff(), 0.0f);
}

// A closed unit cube, each wall an n × n grid lit on the inside, albedo ρ, a point light inside.
// All of the light's flux 4πI lands on the walls, so ∫ E_d dA = 4πI and ∫ L_d dA = 4ρI; all the
// flux the walls reflect, π ∫ L_d dA, lands on the walls again, so ∫ L_i dA = ρ/π · π ∫ L_d dA
// = 4ρ²I. The integrals over the walls are trapezoid sums over the vertices.
struct ClosedCube {
  const Eigen::Vector3d rho{0.8, 0.5, 0.2};
  SurfaceMesh mesh;
  std::vector<double> weights;

  explicit ClosedCube(int n, double side = 1.0) {
    const Eigen::Vector3d ex(1, 0, 0), ey(0, 1, 0), ez(0, 0, 1), o(0, 0, 0);
    const double s = side;
    add_rectangle(mesh, o, s * ex, s * ez, n, n, ey, rho, &weights);       // floor
    add_rectangle(mesh, s * ey, s * ex, s * ez, n, n, -ey, rho, &weights);  // ceiling
    add_rectangle(mesh, o, s * ey, s * ez, n, n, ex, rho, &weights);       // x = 0
    add_rectangle(mesh, s * ex, s * ey, s * ez, n, n, -ex, rho, &weights);  // x = side
    add_rectangle(mesh, o, s * ex, s * ey, n, n, ez, rho, &weights);       // z = 0
    add_rectangle(mesh, s * ez, s * ex, s * ey, n, n, -ez, rho, &weights);  // z = side
  }

  Eigen::Vector3d integral(const Eigen::VectorXf& radiance) const {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (size_t v = 0; v < weights.size(); ++v) sum += weights[v] * radiance.segment<3>(3 * static_cast<Eigen::Index>(v)).cast<double>();
    return sum;
  }
};

TEST(IlluminationIndirect, ClosedCubeConservesFlux) {
  // The flux balance holds at any size: ray offsets scale with the scene (STYLE.md §6).
  for (const double side : {1.0, 1e-3, 1e3}) {
    SCOPED_TRACE("side " + std::to_string(side));
    const ClosedCube cube(32, side);
    auto engine = make_engine(cube.mesh);
    const PointLight light{side * Eigen::Vector3d(0.45, 0.55, 0.4), {1, 2, 3}};
    Eigen::VectorXf direct, indirect;
    engine->direct({light}, engine->all_points(), direct);
    engine->indirect({light}, {64, 0}, engine->all_points(), indirect);
    // Cell means weighted by the cells' areas (a vertex's trapezoid weight is its cell's area but
    // at the faces' corners) integrate the same field.
    GatherOptions cell{64, 0};
    cell.cell_average = true;
    Eigen::VectorXf cell_indirect;
    engine->indirect({light}, cell, engine->all_points(), cell_indirect);
    const Eigen::Vector3d direct_integral = cube.integral(direct);
    const Eigen::Vector3d indirect_integral = cube.integral(indirect);
    const Eigen::Vector3d cell_integral = cube.integral(cell_indirect);
    for (int k = 0; k < 3; ++k) {
      const double expected_direct = 4 * cube.rho[k] * light.intensity[k];
      const double expected_indirect = 4 * cube.rho[k] * cube.rho[k] * light.intensity[k];
      EXPECT_NEAR(direct_integral[k], expected_direct, 2e-3 * expected_direct) << "channel " << k;
      EXPECT_NEAR(indirect_integral[k], expected_indirect, 3e-3 * expected_indirect) << "channel " << k;
      EXPECT_NEAR(cell_integral[k], expected_indirect, 3e-3 * expected_indirect) << "cell average, channel " << k;
    }
  }
}

TEST(IlluminationIndirect, ClosedCubeDoesNotLeakAtItsEdges) {
  // A light outside the cube: every wall's inside is in shadow, and so is every ray's hit — a
  // single ray slipping through a crease would show. (The last light is 2 mm above the ceiling:
  // rays start and stop ~1e-4 × the scene's size off surfaces, so a light closer than that to a
  // wall is out of scope.)
  const ClosedCube cube(16);
  auto engine = make_engine(cube.mesh);
  for (const Eigen::Vector3d& position : {Eigen::Vector3d(-0.5, 0.5, 0.5), Eigen::Vector3d(-0.3, -0.3, -0.3),
                                          Eigen::Vector3d(1.2, 1.2, 0.5), Eigen::Vector3d(0.5, 1.002, 0.5)}) {
    Eigen::VectorXf out;
    engine->direct({{position, {1, 1, 1}}}, engine->all_points(), out);
    EXPECT_TRUE(out.isZero(0)) << "direct, light at " << position.transpose();
    engine->indirect({{position, {1, 1, 1}}}, {32, 3}, engine->all_points(), out);
    EXPECT_TRUE(out.isZero(0)) << "indirect, light at " << position.transpose();
    GatherOptions from_vertices{32, 3};
    from_vertices.direct_from_vertices = true;
    engine->indirect({{position, {1, 1, 1}}}, from_vertices, engine->all_points(), out);
    EXPECT_TRUE(out.isZero(0)) << "indirect from the vertices, light at " << position.transpose();
    from_vertices.cell_average = true;  // rays from all over the cells, up to the creases
    engine->indirect({{position, {1, 1, 1}}}, from_vertices, engine->all_points(), out);
    EXPECT_TRUE(out.isZero(0)) << "indirect over the cells, light at " << position.transpose();
  }
}

// ---- Determinism and linearity ----------------------------------------------------------------

void expect_bitwise_equal(const Eigen::VectorXf& full, const std::vector<int>& points, const Eigen::VectorXf& part,
                          const std::string& what) {
  ASSERT_EQ(part.size(), 3 * static_cast<Eigen::Index>(points.size())) << what;
  for (size_t p = 0; p < points.size(); ++p) {
    for (int k = 0; k < 3; ++k) {
      const float a = full[3 * points[p] + k];
      const float b = part[3 * static_cast<Eigen::Index>(p) + k];
      ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << what << ": point " << points[p] << " channel " << k;
    }
  }
}

TEST(IlluminationGather, APointsValueDoesNotDependOnTheBatch) {
  const SurfaceMesh mesh = cornell_box({3000});
  auto engine = make_engine(mesh);
  const int n = engine->point_count();
  const std::vector<PointLight> lights = {{{0.3, 0.5, 0.25}, {1, 1, 1}}};
  const GatherOptions options{16, 42};
  Eigen::VectorXf full_indirect, full_direct, part;
  engine->indirect(lights, options, engine->all_points(), full_indirect);
  engine->direct(lights, engine->all_points(), full_direct);
  EXPECT_GT(full_indirect.maxCoeff(), 0.0f);

  std::vector<int> subset = {n - 1, 0, 17, 1234, 17, n / 2, 2 * n / 3, 5};
  engine->indirect(lights, options, subset, part);
  expect_bitwise_equal(full_indirect, subset, part, "subset");
  engine->direct(lights, subset, part);
  expect_bitwise_equal(full_direct, subset, part, "direct subset");
  std::reverse(subset.begin(), subset.end());
  engine->indirect(lights, options, subset, part);
  expect_bitwise_equal(full_indirect, subset, part, "reversed subset");
  for (int v : subset) {
    engine->indirect(lights, options, {v}, part);
    expect_bitwise_equal(full_indirect, {v}, part, "single point");
  }
  // The full set reversed: other chunks, other threads.
  std::vector<int> reversed = engine->all_points();
  std::reverse(reversed.begin(), reversed.end());
  engine->indirect(lights, options, reversed, part);
  expect_bitwise_equal(full_indirect, reversed, part, "all points reversed");

  // Another engine over the same surface gives the same values.
  auto again = make_engine(mesh);
  again->indirect(lights, options, engine->all_points(), part);
  expect_bitwise_equal(full_indirect, engine->all_points(), part, "second engine");

  // The seed does pick other directions.
  engine->indirect(lights, {16, 43}, engine->all_points(), part);
  int differ = 0;
  for (Eigen::Index i = 0; i < part.size(); ++i) differ += part[i] != full_indirect[i];
  EXPECT_GT(differ, part.size() / 2);
}

// Issue #38: every gather (stratified, disc lights, the direct light from the vertices, the cell
// average, the cell's shadow rays) is deterministic per point and per seed — a point's value
// alone equals its value in the full gather bit for bit, the same seed repeats, another seed
// draws other directions.
TEST(IlluminationGather, EveryGatherIsDeterministicPerPointAndPerSeed) {
  auto engine = make_engine(cornell_box({2000}));
  const int n = engine->point_count();
  const std::vector<PointLight> lights = {{{0.3, 0.45, 0.25}, {1, 1, 1}}};
  std::vector<GatherOptions> gathers(7);
  gathers[0].sampling = HemisphereSampling::kStratified;
  gathers[1].light_radius = 0.02;
  gathers[1].shadow_rays = 3;
  gathers[2].sampling = HemisphereSampling::kStratified;
  gathers[2].light_radius = 0.01;
  gathers[3].direct_from_vertices = true;  // a subset reads the direct light at fewer vertices
  gathers[4].cell_average = true;
  gathers[5].direct_from_vertices = true;
  gathers[5].cell_average = true;
  gathers[6] = gathers[5];
  gathers[6].cell_shadow_rays = 16;  // the blocks' shadows cross cells at this light
  for (size_t g = 0; g < gathers.size(); ++g) {
    SCOPED_TRACE("gather " + std::to_string(g));
    GatherOptions options = gathers[g];
    options.samples = 24;
    options.seed = 9;
    Eigen::VectorXf full, again, part;
    engine->indirect(lights, options, engine->all_points(), full);
    EXPECT_GT(full.maxCoeff(), 0.0f);
    engine->indirect(lights, options, engine->all_points(), again);
    expect_bitwise_equal(full, engine->all_points(), again, "same seed");
    const std::vector<int> subset = {n - 1, 0, 17, n / 2, 5};
    engine->indirect(lights, options, subset, part);
    expect_bitwise_equal(full, subset, part, "subset");
    for (int v : subset) {
      engine->indirect(lights, options, {v}, part);
      expect_bitwise_equal(full, {v}, part, "single point");
    }
    options.seed = 10;
    engine->indirect(lights, options, engine->all_points(), part);
    int differ = 0;
    for (Eigen::Index i = 0; i < part.size(); ++i) differ += part[i] != full[i];
    EXPECT_GT(differ, part.size() / 2);
  }
}

// Issue #38: indirect_frames gives each light's frame of indirect() bit for bit, for both ways of
// reading the direct light at the hits — with more lights than one block of the shared-ray path,
// and lights on both sides of the blocks.
TEST(IlluminationGather, FramesForManyLightsEqualEachLightsOwnGather) {
  auto engine = make_engine(cornell_box({1500}));
  std::vector<PointLight> lights;
  for (int l = 0; l < 11; ++l) {
    lights.push_back({{0.08 + 0.04 * l, 0.45 - 0.01 * l, 0.1 + 0.03 * l}, {1.0 + l, 1.0, 0.5}});
  }
  lights.push_back({{0.3, 0.3, -0.5}, {1, 1, 1}});  // in front of the open side
  for (const auto& [from_vertices, cell, cell_rays] :
       {std::tuple{false, false, 0}, std::tuple{true, false, 0}, std::tuple{true, true, 0}, std::tuple{true, true, 8}}) {
    SCOPED_TRACE(std::string(from_vertices ? "direct from the vertices" : "shadow rays") +
                 (cell ? ", cell average" : "") + (cell_rays > 0 ? ", cell shadow rays" : ""));
    GatherOptions options{24, 5};
    options.direct_from_vertices = from_vertices;
    options.cell_average = cell;
    options.cell_shadow_rays = cell_rays;
    FrameMatrix frames;
    std::vector<int64_t> progress;
    engine->indirect_frames(lights, options, frames,
                            [&](std::string_view stage, int64_t done, int64_t total) {
                              EXPECT_EQ(stage, "gather");
                              EXPECT_EQ(total, static_cast<int64_t>(lights.size()));
                              progress.push_back(done);
                            });
    ASSERT_EQ(frames.rows(), static_cast<Eigen::Index>(lights.size()));
    ASSERT_EQ(frames.cols(), 3 * static_cast<Eigen::Index>(engine->point_count()));
    ASSERT_FALSE(progress.empty());
    EXPECT_EQ(progress.back(), static_cast<int64_t>(lights.size()));
    EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));
    for (size_t l = 0; l < lights.size(); ++l) {
      Eigen::VectorXf own;
      engine->indirect({lights[l]}, options, engine->all_points(), own);
      EXPECT_GT(own.maxCoeff(), 0.0f) << "light " << l;
      const Eigen::VectorXf row = frames.row(static_cast<Eigen::Index>(l)).transpose();
      expect_bitwise_equal(own, engine->all_points(), row, "light " + std::to_string(l));
    }
  }
}

TEST(IlluminationGatherNoise, SpreadPointsAndRelativeErrorsByHand) {
  // ⌊(2k + 1)·N / (2·count)⌋ for N = 10, count = 4: ⌊10/8⌋, ⌊30/8⌋, ⌊50/8⌋, ⌊70/8⌋.
  EXPECT_EQ(spread_points(10, 4), (std::vector<int>{1, 3, 6, 8}));
  EXPECT_EQ(spread_points(3, 5), (std::vector<int>{0, 1, 2}));
  EXPECT_TRUE(spread_points(0, 5).empty());
  Eigen::VectorXf reference(6), estimate(6);
  reference << 1, 1, 1, 3, 3, 3;  // mean 2; largest point norm 3√3
  estimate << 2, 1, 1, 3, 3, 2;    // errors (1, 0, 0) and (0, 0, −1)
  EXPECT_NEAR(relative_rms_difference(estimate, reference), std::sqrt(2.0 / 6.0) / 2.0, 1e-7);
  EXPECT_NEAR(max_error_over_max(estimate, reference), 1.0 / (3.0 * std::sqrt(3.0)), 1e-7);
}

TEST(IlluminationGather, LinearInTheLights) {
  auto engine = make_engine(cornell_box({2000}));
  const PointLight a{{0.2, 0.5, 0.3}, {1.0, 0.5, 0.25}};
  const PointLight b{{0.4, 0.45, 0.2}, {0.2, 0.7, 1.5}};
  const GatherOptions options{16, 5};
  const std::vector<int> points = engine->all_points();
  for (const bool indirect : {false, true}) {
    auto run = [&](const std::vector<PointLight>& lights) {
      Eigen::VectorXf out;
      if (indirect) {
        engine->indirect(lights, options, points, out);
      } else {
        engine->direct(lights, points, out);
      }
      return out;
    };
    const Eigen::VectorXf both = run({a, b});
    const Eigen::VectorXf only_a = run({a});
    const Eigen::VectorXf only_b = run({b});
    for (Eigen::Index i = 0; i < both.size(); ++i) {
      const double sum = double{only_a[i]} + double{only_b[i]};
      ASSERT_NEAR(both[i], sum, 1e-6 * sum + 1e-30) << (indirect ? "indirect" : "direct") << " value " << i;
    }
    // Doubling the intensity doubles every value exactly (a power of two commutes with rounding).
    PointLight brighter = a;
    brighter.intensity *= 2;
    const Eigen::VectorXf doubled = run({brighter});
    for (Eigen::Index i = 0; i < doubled.size(); ++i) ASSERT_EQ(doubled[i], 2 * only_a[i]) << "value " << i;
  }
}

// ---- Validation --------------------------------------------------------------------------------

void expect_invalid(const Status& status, const std::vector<std::string>& parts) {
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument);
  for (const std::string& part : parts) EXPECT_NE(status.error().message.find(part), std::string::npos) << status.error().message;
}

TEST(IlluminationValidation, ErrorsNameTheField) {
  EXPECT_TRUE(check_gather_options({1, 0}).ok());
  expect_invalid(check_gather_options({0, 0}), {"samples", "0"});
  expect_invalid(check_gather_options({-3, 0}), {"samples", "-3"});
  GatherOptions bad_gather;
  bad_gather.shadow_rays = 0;
  expect_invalid(check_gather_options(bad_gather), {"shadow_rays", "0"});
  bad_gather = GatherOptions{};
  bad_gather.light_radius = -0.5;
  expect_invalid(check_gather_options(bad_gather), {"light_radius", "-0.5"});
  bad_gather = GatherOptions{};
  bad_gather.direct_from_vertices = true;
  EXPECT_TRUE(check_gather_options(bad_gather).ok());
  bad_gather.light_radius = 0.01;
  expect_invalid(check_gather_options(bad_gather), {"light_radius", "direct_from_vertices", "0.01"});
  bad_gather = GatherOptions{};
  bad_gather.cell_shadow_rays = 4;
  expect_invalid(check_gather_options(bad_gather), {"cell_shadow_rays", "direct_from_vertices", "4"});
  bad_gather.direct_from_vertices = true;
  EXPECT_TRUE(check_gather_options(bad_gather).ok());
  bad_gather.cell_shadow_rays = -1;
  expect_invalid(check_gather_options(bad_gather), {"cell_shadow_rays", "-1"});

  const PointLight good{{0.1, 0.2, 0.3}, {1, 1, 1}};
  EXPECT_TRUE(check_lights({good}, "lights").ok());
  EXPECT_TRUE(check_lights(std::vector<PointLight>(64, good), "lights").ok());
  expect_invalid(check_lights({}, "lights"), {"lights", "0"});
  expect_invalid(check_lights(std::vector<PointLight>(65, good), "lights"), {"lights", "65", "64"});
  expect_invalid(check_lights(std::vector<PointLight>(3, good), "lights", 2), {"lights", "3", "2"});
  PointLight bad = good;
  bad.position.y() = std::numeric_limits<double>::quiet_NaN();
  expect_invalid(check_lights({good, bad}, "request.lights"), {"request.lights[1].position", "nan"});
  bad = good;
  bad.intensity.z() = -1;
  expect_invalid(check_lights({bad}, "lights"), {"lights[0].intensity", "-1"});
  bad = good;
  bad.intensity.x() = std::numeric_limits<double>::infinity();
  expect_invalid(check_lights({good, good, bad}, "lights"), {"lights[2].intensity", "inf"});

  SurfaceMesh mesh;
  add_rectangle(mesh, {0, 0, 0}, {1, 0, 0}, {0, 0, 1}, 1, 1, {0, 1, 0}, {0.5, 0.5, 0.5});
  mesh.normals.row(2) *= 2;
  auto engine = IlluminationEngine::create(mesh);
  ASSERT_FALSE(engine.ok());
  EXPECT_EQ(engine.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(engine.error().message.find("surface.normals row 2"), std::string::npos) << engine.error().message;
}

}  // namespace
}  // namespace animspace::illumination
