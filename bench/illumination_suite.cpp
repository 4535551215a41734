// The illumination suite (issue #24): the seeds' second application (Meyer & Anderson 2006 §8;
// 2007 §3.2, Figs. 5 and 10). The Cornell box lit by one point light at each node of a grid under
// the ceiling (18 × 18; the papers' 12 × 12 with --illumination-grid 12) is gathered (one-bounce
// indirect, final gather on Embree), a PMSC model of the RGB radiance is trained on those frames,
// and then for novel lights — inside the
// grid's hull and well outside it (by the walls, at floor level) — the indirect illumination is
// computed at the key points only and reconstructed everywhere.
//
// Per light, against the full gather at every point with the same rays (the baseline, same run):
//   relative_rms_error        RMS over points and channels of (estimate − full) ÷ the frame's
//                             mean indirect radiance
//   max_error_over_frame_max  the largest point error ‖estimate − full‖ ÷ the frame's largest ‖full‖
//                             (max_error_point: where it is); subspace_max_error_over_frame_max:
//                             the same for the full frame's orthogonal projection onto the basis,
//                             the floor of any key choice
//   status                    the soft cache's verdict (hit / blend / miss) for the key values
// Issue #38 item 1 (--illumination-filter-neighbours k > 0): the full calculation is the gather
// through the surface filter, the model is trained on such frames, and its keys are gather_keys's
// (the filter's support gathered and filtered, or --illumination-key-samples rays unfiltered).
// Against the 4096-ray reference at 200 spread points: est_ref (the subspace estimate), full_ref
// (the full calculation), gather_ref (the same gather before the filter) and conv_ref (the
// converged full calculation, --illumination-converged-samples rays, also timed).
// Speed (medians over the inside lights): the full gather, the key gather, the reconstruction
// (pmsc::evaluate_cached) and, through a real animspaced on loopback, the round trip of
// EvaluateKeyPoints with the client's key values, and with the light alone (the server gathers
// the keys).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/scratch_directory.h"
#include "bench/serving.h"
#include "bench/suites.h"
#include "clients/cpp/client.h"
#include "clients/cpp/tools/quantile.h"
#include "core/container/model_container.h"
#include "core/illumination/gather_noise.h"
#include "core/illumination/illumination_model.h"
#include "core/illumination/surface_filter.h"
#include "core/common/atomic_file.h"
#include "core/common/parallel.h"
#include "core/pmsc/pmsc_io.h"
#include "core/render/png.h"
#include "core/render/renderer.h"
#include "harness/daemon_process.h"

namespace animspace::bench {
namespace {

using Clock = std::chrono::steady_clock;
using illumination::PointLight;

constexpr const char* kModelName = "cornell";
constexpr int kTimedRepetitions = 5;  // of the cheap steps (key gather, reconstruction, round trip)
constexpr int kGrainNeighbours = 8;   // grain(): the neighbourhood a frame is compared with

double since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

struct NovelLight {
  PointLight light;
  bool inside = false;
  std::string where;
};

// Inside: a low-discrepancy (R2) set over the training grid's rectangle, in its plane — never a
// grid node. Outside: by each wall at two heights, at floor level clear of the blocks, and the
// room's centre; every one at least a fifth of the room's height below the grid plane or a tenth
// of its width outside the rectangle.
std::vector<NovelLight> novel_lights(const illumination::Box& room, const illumination::LightGrid& grid, int inside,
                                     int outside) {
  const Eigen::Vector3d size = room.max - room.min;
  const double plane = room.max.y() - grid.drop * size.y();
  std::vector<NovelLight> lights;
  const double g = 1.32471795724474602596;  // the plastic number: R2's generator
  for (int k = 1; k <= inside; ++k) {
    const double u = std::fmod(0.5 + k / g, 1.0);
    const double v = std::fmod(0.5 + k / (g * g), 1.0);
    const double x = room.min.x() + size.x() * (grid.inset + (1 - 2 * grid.inset) * u);
    const double z = room.min.z() + size.z() * (grid.inset + (1 - 2 * grid.inset) * v);
    lights.push_back({{{x, plane, z}, Eigen::Vector3d::Ones()}, true, "grid plane"});
  }
  const auto at = [&](double fx, double fy, double fz, const char* where) {
    lights.push_back({{room.min + size.cwiseProduct(Eigen::Vector3d(fx, fy, fz)), Eigen::Vector3d::Ones()}, false,
                      where});
  };
  const std::vector<std::function<void()>> outside_set = {
      [&] { at(0.04, 0.5, 0.5, "left wall"); },     [&] { at(0.96, 0.5, 0.5, "right wall"); },
      [&] { at(0.5, 0.5, 0.96, "back wall"); },     [&] { at(0.04, 0.75, 0.8, "left wall, high"); },
      [&] { at(0.96, 0.75, 0.2, "right wall, high"); }, [&] { at(0.5, 0.75, 0.96, "back wall, high"); },
      [&] { at(0.18, 0.04, 0.8, "floor"); },        [&] { at(0.9, 0.04, 0.15, "floor"); },
      [&] { at(0.85, 0.04, 0.85, "floor"); },       [&] { at(0.3, 0.04, 0.55, "floor"); },
      [&] { at(0.5, 0.5, 0.5, "room centre"); },    [&] { at(0.5, 0.3, 0.1, "front, low"); },
  };
  for (int k = 0; k < outside; ++k) outside_set[static_cast<size_t>(k) % outside_set.size()]();
  return lights;
}

struct Accuracy {
  double relative_rms_error = 0;
  double max_error_over_frame_max = 0;
  double max_error = 0;       // radiance units
  long max_error_point = 0;   // the point where it is
  double estimate_scale = 0;  // S of the estimate: its RMS point radiance
};

Accuracy accuracy(const Eigen::VectorXf& estimate, const Eigen::VectorXf& full) {
  const Eigen::ArrayXd e = (estimate - full).cast<double>().array();
  const double mean = full.cast<double>().mean();
  const long n = full.size() / 3;
  const Eigen::Map<const Eigen::Matrix3Xf> f(full.data(), 3, n);
  const Eigen::Map<const Eigen::Matrix3Xd> d(e.data(), 3, n);
  Accuracy a;
  a.relative_rms_error = std::sqrt(e.square().mean()) / mean;
  a.max_error = d.colwise().norm().maxCoeff(&a.max_error_point);
  a.max_error_over_frame_max = a.max_error / static_cast<double>(f.colwise().norm().maxCoeff());
  a.estimate_scale = std::sqrt(estimate.cast<double>().squaredNorm() / static_cast<double>(n));
  return a;
}

const char* status_name(pmsc::CacheStatus s) {
  return s == pmsc::CacheStatus::kHit ? "hit" : s == pmsc::CacheStatus::kBlend ? "blend" : "miss";
}

// A frame's RGB values at `points` (3·|points|, point-major): what is compared with the reference.
Eigen::VectorXf at_points(const Eigen::VectorXf& frame, const std::vector<int>& points) {
  Eigen::VectorXf out(3 * static_cast<long>(points.size()));
  for (size_t p = 0; p < points.size(); ++p) out.segment<3>(3 * static_cast<long>(p)) = frame.segment<3>(3 * points[p]);
  return out;
}

double median(std::vector<double> values) { return values.empty() ? 0.0 : tools::quantile(std::move(values), 0.5); }

// One frame of the figure: the surface coloured by `radiance` (N·3, drawn white at `white`), or
// by the heat map of `heat` (N, red at heat_max).
render::Scene figure_scene(const illumination::IlluminationEngine& scene, const illumination::SceneView& view,
                           const Eigen::VectorXf* radiance, double white, const Eigen::VectorXf* heat, double heat_max) {
  render::Scene s;
  s.width = 256;
  s.height = 256;
  s.points = scene.surface().vertices;
  s.faces = scene.surface().faces;
  s.normals = scene.surface().normals;
  s.camera = render::Camera{view.eye, view.target, view.up, view.vertical_fov_rad};
  if (radiance != nullptr) {
    s.vertex_colours = Eigen::Map<const PointMatrix>(radiance->data(), scene.point_count(), 3).cwiseMax(0.0f);
    s.exposure = static_cast<float>(1.0 / white);
    s.srgb = true;
    s.shading = render::Shading::kUnlit;
  } else {
    s.heat = *heat;
    s.heat_max = static_cast<float>(heat_max);
    s.shading = render::Shading::kLambert;
  }
  return s;
}

// Issue #38: how grainy a frame looks, as a number. Grain is what varies from a point to its
// neighbours and not in the light: the frame minus its own surface-filtered self (`smoother`: a
// few neighbours on the same face, so that shadow edges and fall-off, which are wider, mostly
// stay), as the RMS over points of ‖x_i − x̃_i‖ ÷ the mean ‖x_i‖. The converged frame's value is
// the floor (its features, and its own small noise); a panel at about that value shows no more
// grain than the converged image.
double grain(const illumination::SurfaceFilter& smoother, const Eigen::VectorXf& frame) {
  Eigen::VectorXf smooth;
  illumination::surface_filter_apply(smoother, frame, smooth);
  const Eigen::Map<const Eigen::Matrix3Xf> x(frame.data(), 3, frame.size() / 3);
  const Eigen::Map<const Eigen::Matrix3Xf> y(smooth.data(), 3, smooth.size() / 3);
  const double mean = static_cast<double>(x.colwise().norm().mean());
  const double rms = std::sqrt(static_cast<double>((x - y).colwise().squaredNorm().mean()));
  return mean > 0 ? rms / mean : 0.0;
}

// One row of the figure: a novel light, its frames' grain (grain() above) and its panels.
struct FigureRow {
  PointLight light;
  Eigen::VectorXf converged, full, estimate;
};

// Meyer & Anderson 2007 Fig. 5, on our scene: per novel light (rows) the converged full
// calculation (issue #38: the reference a renderer would accept), the full calculation the model
// learned, the subspace's (each direct + indirect) and the error of the subspace's indirect against
// the full calculation's, |full − subspace|, red at 5% of the frame's largest indirect radiance.
// Every panel of a row is exposed alike (white at the converged frame's 99th percentile).
void write_figure(const std::string& path, const illumination::IlluminationEngine& scene,
                  const std::vector<FigureRow>& rows) {
  auto renderer = render::make_egl_renderer(render::EglPlatform::kAuto);
  if (!renderer) {
    std::printf("illumination: no figure: %s\n", renderer.error().message.c_str());
    return;
  }
  constexpr int kColumns = 4;
  const illumination::SceneView view = illumination::cornell_view();
  const std::vector<int> all = scene.all_points();
  render::Image sheet;
  sheet.width = kColumns * 256;
  sheet.height = static_cast<int>(rows.size()) * 256;
  sheet.rgba.assign(static_cast<size_t>(sheet.width) * sheet.height * 4, 255);
  for (size_t row = 0; row < rows.size(); ++row) {
    const FigureRow& r = rows[row];
    Eigen::VectorXf direct;
    scene.direct({r.light}, all, direct);
    const Eigen::VectorXf converged_total = direct + r.converged;
    const Eigen::VectorXf full_total = direct + r.full;
    const Eigen::VectorXf served_total = direct + r.estimate;
    std::vector<float> largest(static_cast<size_t>(scene.point_count()));
    for (int i = 0; i < scene.point_count(); ++i) {
      largest[static_cast<size_t>(i)] = converged_total.segment<3>(3 * i).maxCoeff();
    }
    std::nth_element(largest.begin(), largest.begin() + static_cast<long>(0.99 * (largest.size() - 1)), largest.end());
    const double white = largest[static_cast<size_t>(0.99 * (largest.size() - 1))];
    const Eigen::Map<const Eigen::Matrix3Xf> f(r.full.data(), 3, scene.point_count());
    const Eigen::Map<const Eigen::Matrix3Xf> e(r.estimate.data(), 3, scene.point_count());
    const Eigen::VectorXf heat = (f - e).colwise().norm().transpose();
    const double heat_max = 0.05 * f.colwise().norm().maxCoeff();
    const render::Scene panels[kColumns] = {figure_scene(scene, view, &converged_total, white, nullptr, 0),
                                            figure_scene(scene, view, &full_total, white, nullptr, 0),
                                            figure_scene(scene, view, &served_total, white, nullptr, 0),
                                            figure_scene(scene, view, nullptr, 0, &heat, heat_max)};
    for (int column = 0; column < kColumns; ++column) {
      auto image = (*renderer)->render(panels[column]);
      if (!image) {
        std::printf("illumination: no figure: %s\n", image.error().message.c_str());
        return;
      }
      for (int y = 0; y < 256; ++y) {
        std::copy_n(image->rgba.data() + static_cast<size_t>(y) * 256 * 4, 256 * 4,
                    sheet.rgba.data() + ((row * 256 + static_cast<size_t>(y)) * sheet.width + column * 256) * 4);
      }
    }
  }
  auto png = render::encode_png(sheet);
  if (!png || !write_file_atomically(path, *png).ok()) {
    std::printf("illumination: could not write the figure %s\n", path.c_str());
    return;
  }
  std::printf("illumination: figure (rows: novel lights; columns: converged full calculation, full calculation, "
              "subspace, |error| red at 5%% of the frame's largest indirect radiance) written to %s\n", path.c_str());
}

// Issue #38, the gather study: for one novel light inside the hull and each candidate gather, the
// full frame gathered with two seeds (their relative RMS difference: √2 × one gather's noise), the
// error of seed 0 against a reference of kReferenceRays Hammersley rays (same light model, another
// seed; its own noise reported by a second reference seed) at
// kReferencePoints spread points, and the roughness in the light's position (light_roughness: 9
// positions 5 mm apart along x) at kRoughnessPoints spread points, beside the reference's own.
// The candidates cost about the same per point: S hemisphere rays and S·J shadow rays.
constexpr int kReferenceRays = 4096;
// The study's S when --illumination-samples is not given: the original gather's 64 rays.
constexpr int kStudySamples = 64;
constexpr int kReferencePoints = 200;
constexpr int kRoughnessPoints = 400;

struct GatherCandidate {
  std::string name;
  illumination::GatherOptions gather;
};

nlohmann::json gather_study(const illumination::IlluminationEngine& scene, const PointLight& light, int samples) {
  using illumination::HemisphereSampling;
  const auto make = [&](const std::string& name, HemisphereSampling sampling, int s, double radius, int rays,
                        bool from_vertices = false) {
    illumination::GatherOptions g;
    g.samples = s;
    g.sampling = sampling;
    g.light_radius = radius;
    g.shadow_rays = rays;
    g.direct_from_vertices = from_vertices;
    return GatherCandidate{name, g};
  };
  const int half = std::max(1, samples / 2);
  const std::vector<GatherCandidate> candidates = {
      make("hammersley S, point (original)", HemisphereSampling::kHammersley, samples, 0, 1),
      make("stratified S, point", HemisphereSampling::kStratified, samples, 0, 1),
      make("hammersley S, r 1 cm x1", HemisphereSampling::kHammersley, samples, 0.01, 1),
      make("hammersley S/2, r 1 cm x3", HemisphereSampling::kHammersley, half, 0.01, 3),
      make("stratified S/2, r 1 cm x3", HemisphereSampling::kStratified, half, 0.01, 3),
      make("hammersley S, r 2 cm x1", HemisphereSampling::kHammersley, samples, 0.02, 1),
      make("hammersley S/2, r 2 cm x3", HemisphereSampling::kHammersley, half, 0.02, 3),
      // The direct light read at the hits from their triangles' vertices: no shadow ray per hit, so
      // a ray costs half as much and the training lights share the rays (GatherOptions).
      make("hammersley S, vertices", HemisphereSampling::kHammersley, samples, 0, 1, true),
      make("hammersley 4S, vertices", HemisphereSampling::kHammersley, 4 * samples, 0, 1, true),
      make("hammersley 16S, vertices", HemisphereSampling::kHammersley, 16 * samples, 0, 1, true),
      make("hammersley 32S, vertices", HemisphereSampling::kHammersley, 32 * samples, 0, 1, true),
  };
  const std::vector<int> all = scene.all_points();
  const std::vector<int> reference_points = illumination::spread_points(scene.point_count(), kReferencePoints);
  const std::vector<int> roughness_points = illumination::spread_points(scene.point_count(), kRoughnessPoints);
  const Eigen::Vector3d step(0.005, 0, 0);
  const int positions = 9;
  // The references, one per light radius (the shadow rays of a 4096-ray reference: 4 per hit).
  struct Reference {
    double radius;
    Eigen::VectorXf values;
    double roughness;
    double two_seeds;  // the reference's own relative RMS difference from another seed
  };
  std::vector<Reference> references;
  references.reserve(8);  // at most one per radius: references returned stay valid
  const auto reference_for = [&](double radius) -> const Reference& {
    for (const Reference& r : references) {
      if (r.radius == radius) return r;
    }
    illumination::GatherOptions g;
    g.samples = kReferenceRays;
    g.seed = 7777;
    g.light_radius = radius;
    g.shadow_rays = radius > 0 ? 4 : 1;
    Reference r{radius, {}, 0, 0};
    scene.indirect({light}, g, reference_points, r.values);
    Eigen::VectorXf other;
    g.seed = 7778;
    scene.indirect({light}, g, reference_points, other);
    r.two_seeds = illumination::relative_rms_difference(other, r.values);
    g.seed = 7777;
    r.roughness = illumination::light_roughness(scene, light, step, positions, g, roughness_points);
    references.push_back(std::move(r));
    return references.back();
  };
  const Reference& point_reference = reference_for(0);
  std::printf("\nillumination gather study: the point-light reference's own two-seed relative RMS difference %.3f%%\n",
              100 * point_reference.two_seeds);
  std::printf("\nillumination gather study (issue #38): light at (%.3f, %.3f, %.3f); reference %d rays (hammersley, "
              "4 shadow rays per hit for r > 0) at %d spread points; roughness: 9 light positions 5 mm apart along x "
              "at %d points\n",
              light.position.x(), light.position.y(), light.position.z(), kReferenceRays, kReferencePoints,
              kRoughnessPoints);
  std::printf("%-30s %7s %10s %10s %10s %11s %10s %10s %9s\n", "gather", "full_s", "2seeds_rms", "ref_rms",
              "ref_max", "vs_point_ref", "roughness", "ref_rough", "ray_cost");
  nlohmann::json rows = nlohmann::json::array();
  for (const GatherCandidate& c : candidates) {
    illumination::GatherOptions first = c.gather, second = c.gather;
    first.seed = 0;
    second.seed = 1;
    Eigen::VectorXf a, b, a_sampled;
    const auto start = Clock::now();
    scene.indirect({light}, first, all, a);
    const double full_seconds = since(start);
    scene.indirect({light}, second, all, b);
    const double seeds = illumination::relative_rms_difference(a, b);
    scene.indirect({light}, first, reference_points, a_sampled);
    const Reference& reference = reference_for(c.gather.light_radius);
    const double reference_rms = illumination::relative_rms_difference(a_sampled, reference.values);
    const double reference_max = illumination::max_error_over_max(a_sampled, reference.values);
    const double vs_point = illumination::relative_rms_difference(a_sampled, point_reference.values);
    const double roughness = illumination::light_roughness(scene, light, step, positions, first, roughness_points);
    const int ray_cost =
        c.gather.samples * (c.gather.direct_from_vertices ? 1 : 1 + (c.gather.light_radius > 0 ? c.gather.shadow_rays : 1));
    std::printf("%-30s %7.3f %9.3f%% %9.3f%% %9.3f%% %10.3f%% %9.3f%% %9.3f%% %9d\n", c.name.c_str(), full_seconds,
                100 * seeds, 100 * reference_rms, 100 * reference_max, 100 * vs_point, 100 * roughness,
                100 * reference.roughness, ray_cost);
    rows.push_back({{"gather_study", true},
                    {"gather", c.name},
                    {"samples", c.gather.samples},
                    {"sampling", c.gather.sampling == HemisphereSampling::kStratified ? "stratified" : "hammersley"},
                    {"light_radius", c.gather.light_radius},
                    {"shadow_rays", c.gather.shadow_rays},
                    {"direct_from_vertices", c.gather.direct_from_vertices},
                    {"full_gather_seconds", full_seconds},
                    {"two_seed_relative_rms_difference", seeds},
                    {"reference_relative_rms_error", reference_rms},
                    {"reference_max_error_over_max", reference_max},
                    {"point_reference_relative_rms_error", vs_point},
                    {"roughness", roughness},
                    {"reference_roughness", reference.roughness},
                    {"reference_two_seed_relative_rms_difference", reference.two_seeds}});
  }
  // How the original gather converges with its ray count, at the reference points only.
  std::printf("original gather (hammersley, point light) by ray count, at the %d reference points:\n%-8s %10s %10s %10s\n",
              kReferencePoints, "rays", "2seeds_rms", "ref_rms", "ref_max");
  for (const int rays : {samples, 4 * samples, 16 * samples}) {
    illumination::GatherOptions first;
    first.samples = rays;
    illumination::GatherOptions second = first;
    second.seed = 1;
    Eigen::VectorXf a, b;
    scene.indirect({light}, first, reference_points, a);
    scene.indirect({light}, second, reference_points, b);
    const double seeds = illumination::relative_rms_difference(a, b);
    const double reference_rms = illumination::relative_rms_difference(a, point_reference.values);
    const double reference_max = illumination::max_error_over_max(a, point_reference.values);
    std::printf("%-8d %9.3f%% %9.3f%% %9.3f%%\n", rays, 100 * seeds, 100 * reference_rms, 100 * reference_max);
    rows.push_back({{"gather_convergence", true},
                    {"samples", rays},
                    {"two_seed_relative_rms_difference", seeds},
                    {"reference_relative_rms_error", reference_rms},
                    {"reference_max_error_over_max", reference_max}});
  }
  // Issue #38 item 1: the original gather at S rays through the surface filter, by its expected
  // neighbour count k, against the same reference: the filter trades the gather's noise (falling
  // as 1/√(0.6 k)) for a bias that grows with the radius; the two seeds' difference is what is
  // left of the noise.
  std::printf("original gather (%d rays) through the surface filter by neighbour count k, at the %d reference "
              "points:\n%-8s %9s %10s %10s %10s %10s %10s\n",
              samples, kReferencePoints, "k", "radius_m", "2seeds_rms", "ref_rms", "ref_max", "roughness",
              "filter_s");
  illumination::GatherOptions original;
  original.samples = samples;
  illumination::GatherOptions other = original;
  other.seed = 1;
  Eigen::VectorXf gathered, gathered_other;
  scene.indirect({light}, original, all, gathered);
  scene.indirect({light}, other, all, gathered_other);
  for (const auto& [k, linear] : std::vector<std::pair<int, bool>>{
           {0, false}, {8, false}, {16, false}, {32, false}, {64, false}, {16, true}, {32, true}, {64, true},
           {128, true}}) {
    auto filter = illumination::surface_filter_precompute(scene.surface(), {k, 0.9, linear});
    if (!filter) {
      std::printf("illumination: %s\n", filter.error().message.c_str());
      break;
    }
    Eigen::VectorXf a, b;
    const auto start = Clock::now();
    illumination::surface_filter_apply(*filter, gathered, a);
    const double filter_seconds = since(start);
    illumination::surface_filter_apply(*filter, gathered_other, b);
    const Eigen::VectorXf a_sampled = at_points(a, reference_points);
    const double seeds = illumination::relative_rms_difference(a, b);
    const double reference_rms = illumination::relative_rms_difference(a_sampled, point_reference.values);
    const double reference_max = illumination::max_error_over_max(a_sampled, point_reference.values);
    // Roughness in the light's position of the filtered gather: the filter is linear and fixed,
    // so it cannot add steps; it averages those of neighbouring points.
    double roughness = 0;
    {
      std::vector<Eigen::VectorXf> frames(static_cast<size_t>(positions));
      for (int q = 0; q < positions; ++q) {
        PointLight moved = light;
        moved.position += (q - positions / 2) * step;
        Eigen::VectorXf raw;
        scene.indirect({moved}, original, all, raw);
        illumination::surface_filter_apply(*filter, raw, frames[static_cast<size_t>(q)]);
      }
      double sum2 = 0, mean = 0;
      long count = 0;
      for (int q = 0; q < positions; ++q) mean += frames[static_cast<size_t>(q)].cast<double>().mean() / positions;
      for (int q = 1; q + 1 < positions; ++q) {
        for (const int p : roughness_points) {
          const Eigen::Vector3d second = (frames[static_cast<size_t>(q) - 1].segment<3>(3 * p) -
                                          2 * frames[static_cast<size_t>(q)].segment<3>(3 * p) +
                                          frames[static_cast<size_t>(q) + 1].segment<3>(3 * p)).cast<double>();
          sum2 += second.squaredNorm();
          count += 3;
        }
      }
      roughness = mean > 0 ? std::sqrt(sum2 / static_cast<double>(count)) / mean : 0;
    }
    std::printf("%-8s %9.4f %9.3f%% %9.3f%% %9.3f%% %9.3f%% %10.4f\n",
                (std::to_string(k) + (linear ? " lin" : "")).c_str(), filter->radius, 100 * seeds,
                100 * reference_rms, 100 * reference_max, 100 * roughness, filter_seconds);
    rows.push_back({{"filter_study", true},
                    {"samples", samples},
                    {"filter_neighbours", k},
                    {"filter_linear", linear},
                    {"filter_radius", filter->radius},
                    {"filter_seconds", filter_seconds},
                    {"two_seed_relative_rms_difference", seeds},
                    {"reference_relative_rms_error", reference_rms},
                    {"reference_max_error_over_max", reference_max},
                    {"roughness", roughness}});
  }
  return rows;
}

}  // namespace

nlohmann::json run_illumination_suite(const SuiteOptions& options) {
  const IlluminationSuiteOptions& o = options.illumination;
  nlohmann::json results = nlohmann::json::array();
  auto engine = illumination::IlluminationEngine::create(illumination::cornell_box({o.points}));
  if (!engine) {
    std::printf("illumination: %s\n", engine.error().message.c_str());
    return results;
  }
  const illumination::IlluminationEngine& scene = **engine;
  const illumination::Box room = illumination::cornell_room();
  illumination::LightGrid grid;  // 18 × 18 (the papers' 12 × 12: --illumination-grid 12)
  if (o.drop > 0) grid.drop = o.drop;
  if (o.grid > 0) grid.nx = grid.nz = o.grid;
  illumination::IlluminationTrainingOptions training;
  for (const Eigen::Vector3d& p : illumination::light_grid(room, grid)) training.lights.push_back({p, Eigen::Vector3d::Ones()});
  if (o.samples > 0) training.gather.samples = o.samples;  // else the training's default
  training.gather.sampling = o.sampling == "stratified" ? illumination::HemisphereSampling::kStratified
                                                         : illumination::HemisphereSampling::kHammersley;
  training.gather.light_radius = o.light_radius;
  training.gather.shadow_rays = o.shadow_rays;
  training.relative_tolerance = !o.absolute_tolerance;
  if (o.basis_slack >= 0) training.pmsc.held_out_basis_slack = o.basis_slack;
  if (o.max_key_points > 0) training.pmsc.max_key_points = o.max_key_points;
  if (o.error_bound > 0) training.error_bound_fraction = o.error_bound;
  if (o.filter_neighbours >= 0) training.filter.neighbours = o.filter_neighbours;
  training.filter.linear = o.filter_linear;
  training.key_samples = o.key_samples;
  if (o.direct_from_vertices >= 0) training.gather.direct_from_vertices = o.direct_from_vertices != 0;
  if (o.cell_average >= 0) training.gather.cell_average = o.cell_average != 0;
  // The cell's shadow rays make the vertices' stored L_d: off with a shadow ray per hit, unless
  // asked for (which the training then refuses, naming the field).
  if (o.cell_shadow_rays >= 0) {
    training.gather.cell_shadow_rays = o.cell_shadow_rays;
  } else if (!training.gather.direct_from_vertices) {
    training.gather.cell_shadow_rays = 0;
  }
  illumination::GatherOptions keys_gather = training.gather;
  if (o.key_samples > 0) keys_gather.samples = o.key_samples;
  // The converged baseline is the physical gather: a shadow ray from every hit.
  illumination::GatherOptions converged_gather = training.gather;
  converged_gather.samples = o.converged_samples;
  converged_gather.direct_from_vertices = false;
  converged_gather.cell_shadow_rays = 0;
  if (o.gather_study > 0) {
    const std::vector<NovelLight> probe = novel_lights(room, grid, 1, 0);
    for (auto& row : gather_study(scene, probe[0].light, o.samples > 0 ? o.samples : kStudySamples)) results.push_back(row);
    if (o.gather_study == 2) return results;
  }
  std::printf("illumination: Cornell box, %d points, %d gather rays per point (%s, light radius %g m, %d shadow rays, "
              "the direct light at the hits %s, rays from %s); training on %zu lights (%d × %d grid)\n",
              scene.point_count(), training.gather.samples, o.sampling.c_str(), o.light_radius, o.shadow_rays,
              training.gather.direct_from_vertices ? "from the hit triangles' vertices" : "by a shadow ray per hit",
              training.gather.cell_average ? "each vertex's cell" : "the vertices", training.lights.size(), grid.nx,
              grid.nz);
  auto surface_filter = illumination::surface_filter_precompute(scene.surface(), training.filter, "filter");
  if (!surface_filter) {
    std::printf("illumination: %s\n", surface_filter.error().message.c_str());
    return results;
  }
  std::printf("illumination (issue #38 item 1): the full calculation is the %d-ray gather %s; key points gathered with "
              "%d rays%s; the converged full calculation: %d rays, unfiltered\n",
              training.gather.samples,
              surface_filter->enabled() ? ("through the surface filter (" + std::string(o.filter_linear ? "linear, " : "") +
                                           "k = " + std::to_string(training.filter.neighbours) +
                                           ", radius " + std::to_string(surface_filter->radius) + " m)").c_str()
                                        : "unfiltered",
              keys_gather.samples,
              o.key_samples == 0 && surface_filter->enabled() ? " at every point their filters read, then filtered" : "",
              o.converged_samples);

  // The post-filter experiment (--illumination-post-filter): the filter applied to the raw model's
  // reconstruction, F·f̂, against the filtered full calculation F·g and the reference.
  illumination::SurfaceFilterOptions post_options;
  post_options.neighbours = training.filter.enabled() ? 0 : o.post_filter_neighbours;
  auto post_filter = illumination::surface_filter_precompute(scene.surface(), post_options, "post_filter");
  if (!post_filter) {
    std::printf("illumination: %s\n", post_filter.error().message.c_str());
    return results;
  }
  std::vector<double> post_rms_inside, post_max_inside, post_est_ref_inside, post_full_ref_inside, post_s;

  illumination::IlluminationTrainingReport report;
  const auto train_start = Clock::now();
  auto container = illumination::train_illumination(scene, training, "Cornell box (bench)", &report);
  const double train_seconds = since(train_start);
  if (!container) {
    std::printf("illumination: training failed: %s\n", container.error().message.c_str());
    return results;
  }
  auto loaded = pmsc::load(*container, "bench");
  if (!loaded) {
    std::printf("illumination: %s\n", loaded.error().message.c_str());
    return results;
  }
  const pmsc::PmscModel& model = *loaded;
  if (model.relative_tolerance) {
    std::printf("illumination: trained in %.1f s (gathers %.1f s, PMSC %.1f s): M = %d, K = %d key points, "
                "ε = [%.4g, %.4g] × the frame's RMS radiance S, tolerance %.4g S (%.3g of the frame's largest "
                "radiance at the training frames' median peak/RMS %.4g)\n",
                train_seconds, report.gather_seconds, report.pmsc.seconds, model.basis_size(), model.key_point_count(),
                model.epsilon.epsilon_min, model.epsilon.epsilon_max,
                training.tolerance_fraction * report.peak_to_rms_ratio, training.tolerance_fraction,
                report.peak_to_rms_ratio);
  } else {
    std::printf("illumination: trained in %.1f s (gathers %.1f s, PMSC %.1f s): M = %d, K = %d key points, "
                "ε = [%.4g, %.4g] radiance, tolerance %.4g (radiance scale %.4g)\n",
                train_seconds, report.gather_seconds, report.pmsc.seconds, model.basis_size(), model.key_point_count(),
                model.epsilon.epsilon_min, model.epsilon.epsilon_max,
                training.tolerance_fraction * report.radiance_scale, report.radiance_scale);
  }

  const std::vector<int> all = scene.all_points();
  const std::vector<NovelLight> lights = novel_lights(room, grid, o.inside, o.outside);
  // Issue #38: both the subspace's estimate and the full gather against a converged reference
  // (kReferenceRays rays, the training gather's light model, another seed) at kReferencePoints
  // spread points: ref_rms columns, relative RMS as rel_rms.
  const std::vector<int> reference_points = illumination::spread_points(scene.point_count(), kReferencePoints);
  illumination::GatherOptions reference_gather = training.gather;
  reference_gather.samples = kReferenceRays;
  reference_gather.seed = 7777;
  reference_gather.direct_from_vertices = false;  // a shadow ray from every hit: the physical gather
  reference_gather.cell_shadow_rays = 0;
  // (of the same quantity: with cell_average, each vertex's cell mean, as the training's)
  if (reference_gather.light_radius > 0) reference_gather.shadow_rays = std::max(reference_gather.shadow_rays, 4);
  std::printf("\n%-4s %-18s %-7s %9s %9s %9s %7s %9s %9s %9s %9s %9s %9s %9s\n", "#", "where", "inside", "rel_rms",
              "floor", "max/max", "status", "full_s", "keys_ms", "recon_ms", "est_ref", "full_ref", "gather_ref",
              "conv_ref");
  std::vector<double> recon_one_thread_s;
  std::vector<double> full_s, keys_s, recon_s, rms_inside, max_inside, subspace_max_inside, est_ref_inside, full_ref_inside;
  std::vector<double> gather_ref_inside, converged_ref_inside, converged_s, filter_s;
  constexpr size_t kConvergedTimed = 3;  // inside lights whose converged full frame is timed (it costs 16×)
  int hits_inside = 0, flagged_outside = 0, n_inside = 0, n_outside = 0;
  int same_verdict = 0, intensity_trials = 0, hits_within_tolerance = 0;
  std::vector<Eigen::VectorXf> inside_keys;
  std::vector<pmsc::CacheStatus> inside_status;  // the in-process verdicts
  std::vector<Eigen::VectorXf> inside_estimates;
  std::vector<NovelLight> inside_lights;
  // The first three inside lights' frames, for the figure and its grain.
  std::vector<Eigen::VectorXf> inside_full, inside_converged, inside_gathered;
  // Every novel light's gathered frame at once: with the direct light read from the vertices the
  // lights share the rays (indirect_frames, bit for bit each light's own gather), which is what
  // makes a 2,048-ray full calculation at 100k points affordable for 36 lights. The full
  // calculation as the daemon runs it on a miss, one light alone, is timed for the first
  // kFullTimed inside lights then (for every light with a shadow ray per hit, as before).
  constexpr size_t kFullTimed = 3;
  FrameMatrix novel_frames;
  {
    std::vector<PointLight> novel_point_lights;
    for (const NovelLight& novel : lights) novel_point_lights.push_back(novel.light);
    scene.indirect_frames(novel_point_lights, training.gather, novel_frames);
  }
  int timed_frames_differing = 0;
  for (size_t l = 0; l < lights.size(); ++l) {
    const NovelLight& novel = lights[l];
    // The full calculation the model learned: the gather, then the surface filter (issue #38
    // item 1; off when k = 0).
    Eigen::VectorXf gathered = novel_frames.row(static_cast<Eigen::Index>(l)).transpose(), full;
    double full_seconds = std::nan("");
    if (novel.inside && (!training.gather.direct_from_vertices || full_s.size() < kFullTimed)) {
      Eigen::VectorXf alone;
      const auto full_start = Clock::now();
      scene.indirect({novel.light}, training.gather, all, alone);
      full_seconds = since(full_start);
      timed_frames_differing += alone == gathered ? 0 : 1;
    }
    const auto filter_start = Clock::now();
    illumination::surface_filter_apply(*surface_filter, gathered, full);
    const double filter_seconds = since(filter_start);
    if (!std::isnan(full_seconds)) full_seconds += filter_seconds;
    Eigen::VectorXf keys;
    std::vector<double> key_times, recon_times, recon_one_thread_times;
    pmsc::CachedPose cached;
    for (int r = 0; r < kTimedRepetitions; ++r) {
      const auto k0 = Clock::now();
      illumination::gather_keys(scene, training.gather, &*surface_filter, o.key_samples, {novel.light},
                                model.key_points, keys);
      key_times.push_back(since(k0));
      // Issue #38 item 3: beside the reconstruction (its rows split across the cores when large),
      // the one before this item, on one thread, in the same run. They take turns at going first:
      // the second finds the basis the first left in the caches.
      pmsc::CachedPose one_thread;
      for (int turn = 0; turn < 2; ++turn) {
        const bool split = (turn == 0) == (r % 2 == 0);
        set_thread_limit(split ? 0 : 1);
        const auto r0 = Clock::now();
        pmsc::evaluate_cached(model, keys, nullptr, split ? cached : one_thread);
        (split ? recon_times : recon_one_thread_times).push_back(since(r0));
      }
      set_thread_limit(0);
    }
    const Accuracy a = accuracy(cached.points, full);
    // The floor of any key choice: the full frame's orthogonal projection onto the subspace.
    const Eigen::VectorXf centred = full - model.mean;
    const Eigen::VectorXf projected = model.mean + model.basis * (model.basis.transpose() * centred);
    const Accuracy floor = accuracy(projected, full);
    Eigen::VectorXf reference, converged_sampled;
    scene.indirect({novel.light}, reference_gather, reference_points, reference);
    const Eigen::VectorXf estimate_sampled = at_points(cached.points, reference_points);
    const Eigen::VectorXf full_sampled = at_points(full, reference_points);
    const Eigen::VectorXf gather_sampled = at_points(gathered, reference_points);
    // The converged full calculation: the gather's value at a point does not depend on the other
    // points gathered, so its error at the reference points is that of its full frame; the full
    // frame is gathered (and timed) for the first few inside lights only.
    scene.indirect({novel.light}, converged_gather, reference_points, converged_sampled);
    if (novel.inside && converged_s.size() < kConvergedTimed) {
      Eigen::VectorXf converged;
      const auto converged_start = Clock::now();
      scene.indirect({novel.light}, converged_gather, all, converged);
      converged_s.push_back(since(converged_start));
      inside_converged.push_back(std::move(converged));
    }
    if (novel.inside && post_filter->enabled()) {
      Eigen::VectorXf post_estimate, post_full;
      const auto post_start = Clock::now();
      illumination::surface_filter_apply(*post_filter, cached.points, post_estimate);
      post_s.push_back(since(post_start));
      illumination::surface_filter_apply(*post_filter, gathered, post_full);
      const Accuracy post = accuracy(post_estimate, post_full);
      post_rms_inside.push_back(post.relative_rms_error);
      post_max_inside.push_back(post.max_error_over_frame_max);
      post_est_ref_inside.push_back(
          illumination::relative_rms_difference(at_points(post_estimate, reference_points), reference));
      post_full_ref_inside.push_back(
          illumination::relative_rms_difference(at_points(post_full, reference_points), reference));
    }
    const double estimate_vs_reference = illumination::relative_rms_difference(estimate_sampled, reference);
    const double full_vs_reference = illumination::relative_rms_difference(full_sampled, reference);
    const double gather_vs_reference = illumination::relative_rms_difference(gather_sampled, reference);
    const double converged_vs_reference = illumination::relative_rms_difference(converged_sampled, reference);
    nlohmann::json row{{"light", l},
                       {"position", {novel.light.position.x(), novel.light.position.y(), novel.light.position.z()}},
                       {"where", novel.where},
                       {"inside_hull", novel.inside},
                       {"relative_rms_error", a.relative_rms_error},
                       {"subspace_relative_rms_error", floor.relative_rms_error},
                       {"max_error_over_frame_max", a.max_error_over_frame_max},
                       {"subspace_max_error_over_frame_max", floor.max_error_over_frame_max},
                       {"max_error_point", {scene.surface().vertices(a.max_error_point, 0),
                                            scene.surface().vertices(a.max_error_point, 1),
                                            scene.surface().vertices(a.max_error_point, 2)}},
                       {"status", status_name(cached.status)},
                       {"key_point_error", cached.key_point_error},
                       {"full_gather_seconds", full_seconds},
                       {"key_gather_seconds", median(key_times)},
                       {"reconstruct_seconds", median(recon_times)},
                       {"reconstruct_one_thread_seconds", median(recon_one_thread_times)},
                       {"estimate_reference_relative_rms_error", estimate_vs_reference},
                       {"full_reference_relative_rms_error", full_vs_reference},
                       {"gather_reference_relative_rms_error", gather_vs_reference},
                       {"converged_reference_relative_rms_error", converged_vs_reference},
                       {"filter_seconds", filter_seconds}};
    std::printf("%-4zu %-18s %-7s %8.3f%% %8.3f%% %8.2f%% %7s %9.3f %9.3f %9.3f %8.3f%% %8.3f%% %8.3f%% %8.3f%%\n", l,
                novel.where.c_str(), novel.inside ? "yes" : "no", 100 * a.relative_rms_error,
                100 * floor.relative_rms_error, 100 * a.max_error_over_frame_max, status_name(cached.status),
                full_seconds, 1e3 * median(key_times), 1e3 * median(recon_times), 100 * estimate_vs_reference,
                100 * full_vs_reference, 100 * gather_vs_reference, 100 * converged_vs_reference);
    results.push_back(row);
    if (novel.inside) {
      ++n_inside;
      hits_inside += cached.status == pmsc::CacheStatus::kHit ? 1 : 0;
      // Issue #38 item 2: the same light ten times dimmer and ten times brighter (the radiance is
      // linear in the intensity, so its keys are the keys scaled) should get the same verdict.
      for (const float intensity : {0.1f, 10.0f}) {
        pmsc::CachedPose scaled;
        pmsc::evaluate_cached(model, Eigen::VectorXf(intensity * keys), nullptr, scaled);
        same_verdict += scaled.status == cached.status ? 1 : 0;
        ++intensity_trials;
      }
      // A HIT within the tolerance the model states: of the frame's own scale when relative.
      if (cached.status == pmsc::CacheStatus::kHit) {
        const double tolerance = model.relative_tolerance
                                     ? training.tolerance_fraction * report.peak_to_rms_ratio * a.estimate_scale
                                     : training.tolerance_fraction * report.radiance_scale;
        hits_within_tolerance += a.max_error <= tolerance ? 1 : 0;
      }
      rms_inside.push_back(a.relative_rms_error);
      max_inside.push_back(a.max_error_over_frame_max);
      subspace_max_inside.push_back(floor.max_error_over_frame_max);
      est_ref_inside.push_back(estimate_vs_reference);
      full_ref_inside.push_back(full_vs_reference);
      gather_ref_inside.push_back(gather_vs_reference);
      converged_ref_inside.push_back(converged_vs_reference);
      filter_s.push_back(filter_seconds);
      if (!std::isnan(full_seconds)) full_s.push_back(full_seconds);
      keys_s.push_back(median(key_times));
      recon_s.push_back(median(recon_times));
      recon_one_thread_s.push_back(median(recon_one_thread_times));
      inside_keys.push_back(keys);
      inside_status.push_back(cached.status);
      inside_estimates.push_back(cached.points);
      inside_lights.push_back(novel);
      if (inside_full.size() < 3) {
        inside_full.push_back(full);
        inside_gathered.push_back(gathered);
      }
    } else {
      ++n_outside;
      flagged_outside += cached.status != pmsc::CacheStatus::kHit ? 1 : 0;
    }
  }
  // Issue #38: the figure's rows, and their grain (grain() above, k = 8 neighbours) for the
  // converged full calculation, the full calculation, the subspace estimate and the gather before
  // the surface filter (what the figure showed before issue #38 item 1: the measure's scale).
  std::vector<FigureRow> figure_rows;
  for (size_t l = 0; l < std::min(inside_full.size(), inside_converged.size()); ++l) {
    figure_rows.push_back({inside_lights[l].light, inside_converged[l], inside_full[l], inside_estimates[l]});
  }
  illumination::SurfaceFilterOptions grain_options;
  grain_options.neighbours = kGrainNeighbours;
  auto grain_smoother = illumination::surface_filter_precompute(scene.surface(), grain_options, "grain");
  nlohmann::json figure_grain = nlohmann::json::array();
  std::vector<double> grain_ratio_full, grain_ratio_estimate;
  for (size_t l = 0; l < figure_rows.size() && grain_smoother; ++l) {
    const FigureRow& r = figure_rows[l];
    const double g_converged = grain(*grain_smoother, r.converged), g_full = grain(*grain_smoother, r.full),
                 g_estimate = grain(*grain_smoother, r.estimate), g_gather = grain(*grain_smoother, inside_gathered[l]);
    figure_grain.push_back({{"converged", g_converged}, {"full", g_full}, {"subspace", g_estimate}, {"gather", g_gather}});
    if (g_converged > 0) {
      grain_ratio_full.push_back(g_full / g_converged);
      grain_ratio_estimate.push_back(g_estimate / g_converged);
    }
    std::printf("figure row %zu grain (RMS of the frame minus its %d-neighbour filtered self ÷ mean radiance): converged "
                "%.2f%%, full calculation %.2f%% (%.2f×), subspace %.2f%% (%.2f×); the gather unfiltered %.2f%% (%.2f×)\n",
                l, kGrainNeighbours, 100 * g_converged, 100 * g_full, g_converged > 0 ? g_full / g_converged : 0.0,
                100 * g_estimate, g_converged > 0 ? g_estimate / g_converged : 0.0, 100 * g_gather,
                g_converged > 0 ? g_gather / g_converged : 0.0);
  }
  if (!o.figure.empty() && !figure_rows.empty()) write_figure(o.figure, scene, figure_rows);
  const double full_gather = median(full_s), key_gather = median(keys_s), reconstruct = median(recon_s);
  const double speedup_in_process = full_gather / (key_gather + reconstruct);
  const double converged_full = median(converged_s);
  const double speedup_vs_converged = converged_full / (key_gather + reconstruct);

  // Served: the same model from a real daemon on loopback, inside lights only (hits: what the
  // soft cache answers from the subspace alone).
  double round_trip = 0, round_trip_light = 0, served_difference = 0;
  int served_light_misses = 0;  // in-process hits the daemon's light-alone answer did not call HIT
  std::string served_problem, light_alone_problem;
  try {
    ScratchDirectory scratch("illumination");
    const auto dir = scratch.path() / "repository" / kModelName / "1";
    std::filesystem::create_directories(dir);
    if (Status written = container::write_file(dir / "model.anim", *container); !written.ok()) {
      throw std::runtime_error(written.error().message);
    }
    harness::DaemonProcess daemon({"--model-repository", (scratch.path() / "repository").string(), "--log-level",
                                   "warn", "--miss-log-fsync", "never", "--renderer", "none"},
                                  scratch.path());
    if (!wait_until_serving(daemon.address(), std::chrono::seconds(120))) {
      throw std::runtime_error("the daemon never reported SERVING:\n" + daemon.log());
    }
    // A deadline that a light-alone blend or miss outlasts only if the daemon is stuck: the daemon
    // completes one with its full calculation (about a minute at 100k converged points).
    ClientOptions client_options;
    client_options.deadline = std::chrono::minutes(10);
    Client client(daemon.address(), client_options);
    std::vector<double> trips, trips_light;
    int light_alone_misses = 0;
    for (size_t l = 0; l < inside_keys.size(); ++l) {
      bool light_alone = inside_status[l] == pmsc::CacheStatus::kHit;
      KeyPointPose pose;
      pose.key_values = std::span<const float>(inside_keys[l].data(), static_cast<size_t>(inside_keys[l].size()));
      const std::vector<animspace::PointLight> light_set{
          {{inside_lights[l].light.position.x(), inside_lights[l].light.position.y(),
            inside_lights[l].light.position.z()},
           {}}};
      KeyPointPose by_light;
      by_light.lights = light_set;
      for (int r = 0; r < kTimedRepetitions; ++r) {
        // The client's keys and no engine input: the daemon answers the subspace estimate for any
        // verdict (full_evaluation_needed on a blend or miss), the same work as in process.
        const auto t0 = Clock::now();
        const PoseResult served = client.evaluate_key_points(kModelName, pose);
        trips.push_back(since(t0));
        if (r == 0) {
          const Eigen::Map<const Eigen::VectorXf> points(served.points.values.data(),
                                                         static_cast<long>(served.points.values.size()));
          if (points.size() != inside_estimates[l].size()) throw std::runtime_error("served a different point count");
          served_difference =
              std::max(served_difference, static_cast<double>((points - inside_estimates[l]).cwiseAbs().maxCoeff()));
        }
        // The light alone: the daemon gathers the keys and, on a blend or miss, fails through to
        // its full gather — so only hits time the key-point path, and only lights that were hits
        // in process are sent. The daemon also gathers the check points, which can turn an
        // in-process hit into a blend or miss that it completes with the full calculation: that
        // light is then counted (light_set_misses) and not sent again.
        if (!light_alone || !light_alone_problem.empty()) continue;
        try {
          const auto t1 = Clock::now();
          const PoseResult served_light = client.evaluate_key_points(kModelName, by_light);
          if (served_light.status == v1::CACHE_STATUS_HIT) {
            trips_light.push_back(since(t1));
          } else {
            ++light_alone_misses;
            light_alone = false;
          }
        } catch (const std::exception& e) {
          light_alone_problem = e.what();
          std::printf("illumination: light-alone served rows stopped at light %zu: %s\n", l, e.what());
        }
      }
    }
    round_trip = median(trips);
    round_trip_light = median(trips_light);
    served_light_misses = light_alone_misses;
  } catch (const std::exception& e) {
    served_problem = e.what();
    std::printf("illumination: served rows skipped: %s\n", e.what());
  }
  const double speedup_served = round_trip > 0 ? full_gather / (key_gather + round_trip) : 0;
  const double speedup_served_light = round_trip_light > 0 ? full_gather / round_trip_light : 0;

  const double hit_rate_inside = n_inside > 0 ? static_cast<double>(hits_inside) / n_inside : 0;
  const double recall_outside = n_outside > 0 ? static_cast<double>(flagged_outside) / n_outside : 0;
  nlohmann::json summary{{"summary", true},
                         {"points", scene.point_count()},
                         {"samples", training.gather.samples},
                         {"direct_from_vertices", training.gather.direct_from_vertices},
                         {"cell_average", training.gather.cell_average},
                         {"cell_shadow_rays", training.gather.cell_shadow_rays},
                         {"full_frames_timed", full_s.size()},
                         {"timed_full_frames_differing_from_shared_rays", timed_frames_differing},
                         {"training_lights", training.lights.size()},
                         {"key_points", model.key_point_count()},
                         {"error_bound_fraction", training.error_bound_fraction},
                         {"basis", model.basis_size()},
                         {"train_seconds", train_seconds},
                         {"training_gather_seconds", report.gather_seconds},
                         {"pmsc_training_seconds", report.pmsc.seconds},
                         {"full_gather_seconds", full_gather},
                         {"key_gather_seconds", key_gather},
                         {"reconstruct_seconds", reconstruct},
                         {"reconstruct_one_thread_seconds", median(recon_one_thread_s)},
                         {"reconstruct_threads", thread_count()},
                         {"held_out_basis_slack", training.pmsc.held_out_basis_slack},
                         {"held_out_relative_rms", report.pmsc.held_out_relative_rms},
                         {"pmsc_pca_seconds", report.pmsc.pca_seconds},
                         {"pmsc_key_selection_seconds", report.pmsc.key_selection_seconds},
                         {"pmsc_calibration_seconds", report.pmsc.calibration_seconds},
                         {"round_trip_seconds", round_trip},
                         {"round_trip_light_set_seconds", round_trip_light},  // hits only
                         {"served_light_set_not_hit", served_light_misses},
                         {"speedup_in_process", speedup_in_process},
                         {"speedup_served", speedup_served},
                         {"speedup_served_light_set", speedup_served_light},
                         {"served_max_difference", served_difference},
                         {"median_relative_rms_error_inside", median(rms_inside)},
                         {"median_estimate_reference_relative_rms_error_inside", median(est_ref_inside)},
                         {"median_full_reference_relative_rms_error_inside", median(full_ref_inside)},
                         {"median_gather_reference_relative_rms_error_inside", median(gather_ref_inside)},
                         {"median_converged_reference_relative_rms_error_inside", median(converged_ref_inside)},
                         {"filter_neighbours", training.filter.neighbours},
                         {"filter_linear", o.filter_linear},
                         {"filter_radius", surface_filter->radius},
                         {"filter_seconds", median(filter_s)},
                         {"key_samples", keys_gather.samples},
                         {"converged_samples", o.converged_samples},
                         {"figure_grain", figure_grain},
                         {"median_grain_over_converged_full", median(grain_ratio_full)},
                         {"median_grain_over_converged_subspace", median(grain_ratio_estimate)},
                         {"converged_full_gather_seconds", converged_full},
                         {"speedup_vs_converged_in_process", speedup_vs_converged},
                         {"p95_max_error_over_frame_max_inside", max_inside.empty() ? 0.0 : tools::quantile(max_inside, 0.95)},
                         {"p95_subspace_max_error_over_frame_max_inside",
                          subspace_max_inside.empty() ? 0.0 : tools::quantile(subspace_max_inside, 0.95)},
                         {"hit_rate_inside", hit_rate_inside},
                         {"recall_outside", recall_outside},
                         {"epsilon_min", model.epsilon.epsilon_min},
                         {"epsilon_max", model.epsilon.epsilon_max},
                         {"radiance_scale", report.radiance_scale},
                         {"relative_tolerance", model.relative_tolerance},
                         {"same_verdict_at_0.1x_and_10x_inside",
                          intensity_trials > 0 ? static_cast<double>(same_verdict) / intensity_trials : 0.0},
                         {"hits_within_tolerance_inside",
                          hits_inside > 0 ? static_cast<double>(hits_within_tolerance) / hits_inside : 1.0}};
  if (!served_problem.empty()) summary["served_problem"] = served_problem;
  if (!light_alone_problem.empty()) summary["served_light_set_problem"] = light_alone_problem;
  if (post_filter->enabled()) {
    summary["post_filter_neighbours"] = post_options.neighbours;
    summary["post_filter_median_relative_rms_error_inside"] = median(post_rms_inside);
    summary["post_filter_p95_max_error_over_frame_max_inside"] =
        post_max_inside.empty() ? 0.0 : tools::quantile(post_max_inside, 0.95);
    summary["post_filter_median_estimate_reference_relative_rms_error_inside"] = median(post_est_ref_inside);
    summary["post_filter_median_full_reference_relative_rms_error_inside"] = median(post_full_ref_inside);
    summary["post_filter_seconds"] = median(post_s);
    summary["post_filter_speedup_in_process"] = full_gather / (key_gather + reconstruct + median(post_s));
  }
  results.push_back(summary);
  std::printf("\ninside the hull (%d lights): median relative RMS %.3f%% of the mean radiance, p95 max error %.2f%% of "
              "the frame max (the projection onto the basis: %.2f%%), hit rate %.2f\n",
              n_inside, 100 * median(rms_inside), 100 * summary["p95_max_error_over_frame_max_inside"].get<double>(),
              100 * summary["p95_subspace_max_error_over_frame_max_inside"].get<double>(), hit_rate_inside);
  std::printf("against a %d-ray reference at %d points (inside, medians): subspace estimate %.3f%%, full calculation "
              "%.3f%% (the %d-ray gather %.3f%% before the filter), converged full calculation (%d rays) %.3f%% of the "
              "mean radiance\n",
              kReferenceRays, kReferencePoints, 100 * median(est_ref_inside), 100 * median(full_ref_inside), training.gather.samples,
              100 * median(gather_ref_inside), o.converged_samples, 100 * median(converged_ref_inside));
  if (post_filter->enabled()) {
    std::printf("post-filter experiment (k = %d on the raw model's reconstruction; inside, medians): F·f̂ against F·g "
                "%.3f%% RMS, p95 max %.2f%% of the frame max; against the reference F·f̂ %.3f%%, F·g %.3f%%; filter "
                "%.3f ms: %.0f× against the raw full calculation\n",
                post_options.neighbours, 100 * median(post_rms_inside),
                100 * summary["post_filter_p95_max_error_over_frame_max_inside"].get<double>(),
                100 * median(post_est_ref_inside), 100 * median(post_full_ref_inside), 1e3 * median(post_s),
                summary["post_filter_speedup_in_process"].get<double>());
  }
  std::printf("outside (%d lights): flagged (blend or miss) %.2f\n", n_outside, recall_outside);
  std::printf("tolerance %s: the same verdict at 0.1× and 10× the light's intensity for %.2f of the inside lights; "
              "%d of %d inside hits within the tolerance\n",
              model.relative_tolerance ? "relative to each frame" : "in radiance units",
              summary["same_verdict_at_0.1x_and_10x_inside"].get<double>(), hits_within_tolerance, hits_inside);
  std::printf("the full calculation timed for %zu inside lights, one light alone (%d of them differ from the frame "
              "gathered with the lights sharing the rays)\n",
              full_s.size(), timed_frames_differing);
  std::printf("full calculation %.3f s (filter %.3f s of it); keys (%d rays) %.3f ms + reconstruction %.3f ms: %.0f× in "
              "process; the converged full calculation %.3f s: %.0f×\n",
              full_gather, median(filter_s), keys_gather.samples, 1e3 * key_gather, 1e3 * reconstruct, speedup_in_process,
              converged_full, speedup_vs_converged);
  std::printf("served: round trip %.3f ms with the client's keys (%.0f× with the key gather), %.3f ms with the light "
              "alone (hits; %.0f×); served points differ from in-process by ≤ %g\n",
              1e3 * round_trip, speedup_served, 1e3 * round_trip_light, speedup_served_light, served_difference);
  std::printf("training: %.1f s for %zu frames (%.1f s gathering)\n", train_seconds, training.lights.size(),
              report.gather_seconds);
  // Issue #38 item 3: the reconstruction on every core against one thread in this run, the basis
  // size and the rule that chose it, and where the PMSC training's time went.
  std::printf("reconstruction %.3f ms on up to %lld threads, %.3f ms on one (%.2f×); M = %d%s\n", 1e3 * reconstruct,
              static_cast<long long>(thread_count()), 1e3 * median(recon_one_thread_s),
              reconstruct > 0 ? median(recon_one_thread_s) / reconstruct : 0.0, model.basis_size(),
              training.pmsc.held_out_basis_slack > 0 ? " (held-out rule)" : "");
  const std::vector<double>& curve = report.pmsc.held_out_relative_rms;
  if (!curve.empty()) {
    std::printf("held-out relative RMS projection error by M (slack %g: the smallest M within %g× the best):",
                training.pmsc.held_out_basis_slack, 1 + training.pmsc.held_out_basis_slack);
    for (size_t k = 1; k < curve.size(); k += k < 10 ? 1 : 10) std::printf(" %zu:%.4f", k, curve[k]);
    std::printf(" %zu:%.4f\n", curve.size() - 1, curve.back());
  }
  std::printf("PMSC training %.1f s: PCA and M %.1f s, key points %.1f s, calibration folds %.1f s\n",
              report.pmsc.seconds, report.pmsc.pca_seconds, report.pmsc.key_selection_seconds,
              report.pmsc.calibration_seconds);
  return results;
}

}  // namespace animspace::bench
