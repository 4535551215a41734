#include "core/illumination/illumination_io.h"

#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>
#include <utility>

#include "core/common/format.h"
#include "core/container/sections.h"

namespace animspace::illumination {

namespace {

constexpr const char* kSamplesKey = "illumination.samples";
constexpr const char* kSeedKey = "illumination.seed";
constexpr const char* kQuantityKey = "illumination.quantity";
// Issue #38; absent in older files, which then load as the original gather (Hammersley, point
// light). Written only when they differ from that, so older readers see unchanged files.
constexpr const char* kSamplingKey = "illumination.sampling";
constexpr const char* kLightRadiusKey = "illumination.light_radius";
constexpr const char* kShadowRaysKey = "illumination.shadow_rays";
// Issue #38 item 1; absent in older files, which then load unfiltered with the keys gathered as
// the frames were.
constexpr const char* kFilterNeighboursKey = "illumination.filter_neighbours";
constexpr const char* kFilterNormalKey = "illumination.filter_min_normal_cosine";
constexpr const char* kKeySamplesKey = "illumination.key_samples";
constexpr const char* kFilterLinearKey = "illumination.filter_linear";
// Issue #38: "vertices" when the gather reads the direct light at its hits from the hit
// triangle's vertices (GatherOptions::direct_from_vertices); absent in older files and for the
// gather with a shadow ray from every hit.
constexpr const char* kDirectAtHitsKey = "illumination.direct_at_hits";
// Issue #38: "cell" when a vertex's rays leave from points of its cell (GatherOptions::
// cell_average); absent in older files and for rays from the vertex itself.
constexpr const char* kRayOriginsKey = "illumination.ray_origins";
// Issue #38: the shadow rays from each vertex's cell for its stored direct light
// (GatherOptions::cell_shadow_rays); absent in older files and for the vertex's own shadow ray.
constexpr const char* kCellShadowRaysKey = "illumination.cell_shadow_rays";

Error named(const Error& e, const std::string& source) { return Error{e.code, source + ": " + e.message}; }

// A gather choice written as `key` = `marker` only when made: absent (or `absent`) reads as the
// other choice, so every file from before the key loads as it did. Any other value is refused
// naming the file, the key and the value.
Result<bool> read_marker(const container::ModelContainer& in, const char* key, const std::string& marker,
                         const std::string& absent, const std::string& source) {
  const std::string value = in.metadata_value(key, absent);
  if (value == marker || value == absent) return value == marker;
  return make_error(ErrorCode::kInvalidArgument,
                    source + ": metadata " + key + " should be '" + marker + "' or absent, got '" + value + "'");
}

}  // namespace

SceneView cornell_view() {
  SceneView view;
  view.eye = Eigen::Vector3d(0.278, 0.273, -0.800);
  view.target = Eigen::Vector3d(0.278, 0.273, 0.0);
  view.up = Eigen::Vector3d::UnitY();
  view.vertical_fov_rad = 2 * std::atan(0.0125 / 0.035);
  return view;
}

void attach_illumination(container::ModelContainer& out, const IlluminationSetup& setup) {
  out.set_points(container::sections::kRestPoints, setup.surface.vertices);
  out.set_faces(container::sections::kFaces, setup.surface.faces);
  out.set_points(sections::kNormals, setup.surface.normals);
  out.set_points(sections::kAlbedo, setup.surface.albedo);
  container::Float64Matrix lights(static_cast<long>(setup.training_lights.size()), 6);
  for (size_t f = 0; f < setup.training_lights.size(); ++f) {
    lights.row(static_cast<long>(f)) << setup.training_lights[f].position.transpose(),
        setup.training_lights[f].intensity.transpose();
  }
  out.set_matrix(sections::kTrainingLights, lights);
  if (setup.view) {
    container::Float64Matrix view(1, 10);
    view << setup.view->eye.transpose(), setup.view->target.transpose(), setup.view->up.transpose(),
        setup.view->vertical_fov_rad;
    out.set_matrix(sections::kView, view);
  }
  out.metadata()[kSamplesKey] = std::to_string(setup.gather.samples);
  out.metadata()[kSeedKey] = std::to_string(setup.gather.seed);
  out.metadata()[kQuantityKey] = setup.quantity;
  if (setup.gather.sampling == HemisphereSampling::kStratified) out.metadata()[kSamplingKey] = "stratified";
  if (setup.gather.light_radius > 0) {
    out.metadata()[kLightRadiusKey] = format_number(setup.gather.light_radius);
    out.metadata()[kShadowRaysKey] = std::to_string(setup.gather.shadow_rays);
  }
  if (setup.gather.direct_from_vertices) out.metadata()[kDirectAtHitsKey] = "vertices";
  if (setup.gather.cell_average) out.metadata()[kRayOriginsKey] = "cell";
  if (setup.gather.cell_shadow_rays > 0) out.metadata()[kCellShadowRaysKey] = std::to_string(setup.gather.cell_shadow_rays);
  if (setup.filter.enabled()) {
    out.metadata()[kFilterNeighboursKey] = std::to_string(setup.filter.neighbours);
    out.metadata()[kFilterNormalKey] = format_number(setup.filter.min_normal_cosine);
    if (setup.filter.linear) out.metadata()[kFilterLinearKey] = "true";
  }
  if (setup.key_samples > 0 && setup.key_samples != setup.gather.samples) {
    out.metadata()[kKeySamplesKey] = std::to_string(setup.key_samples);
  }
}

bool has_illumination(const container::ModelContainer& in) { return in.has_section(sections::kAlbedo); }

Result<IlluminationSetup> load_illumination(const container::ModelContainer& in, const std::string& source) {
  IlluminationSetup setup;
  auto vertices = in.points(container::sections::kRestPoints);
  if (!vertices) return named(vertices.error(), source);
  auto faces = in.faces(container::sections::kFaces);
  if (!faces) return named(faces.error(), source);
  auto normals = in.points(sections::kNormals);
  if (!normals) return named(normals.error(), source);
  auto albedo = in.points(sections::kAlbedo);
  if (!albedo) return named(albedo.error(), source);
  const long n = vertices->rows();
  if (normals->rows() != n) return container::section_shape_error(source, sections::kNormals, std::to_string(n) + "×3", normals->rows(), 3);
  if (albedo->rows() != n) return container::section_shape_error(source, sections::kAlbedo, std::to_string(n) + "×3", albedo->rows(), 3);
  setup.surface = {std::move(*vertices), std::move(*normals), std::move(*albedo), std::move(*faces)};
  ANIMSPACE_RETURN_IF_ERROR(check_surface(setup.surface, source));

  auto lights = in.double_matrix(sections::kTrainingLights, 6);
  if (!lights) return named(lights.error(), source);
  for (long f = 0; f < lights->rows(); ++f) {
    setup.training_lights.push_back({lights->row(f).head<3>().transpose(), lights->row(f).tail<3>().transpose()});
  }
  if (in.has_section(sections::kView)) {
    auto view = in.double_matrix(sections::kView, 10);
    if (!view) return named(view.error(), source);
    if (view->rows() != 1) return container::section_shape_error(source, sections::kView, "1×10", view->rows(), 10);
    SceneView v;
    v.eye = view->row(0).segment<3>(0).transpose();
    v.target = view->row(0).segment<3>(3).transpose();
    v.up = view->row(0).segment<3>(6).transpose();
    v.vertical_fov_rad = (*view)(0, 9);
    if (!view->allFinite() || !(v.vertical_fov_rad > 0 && v.vertical_fov_rad < M_PI) || (v.eye - v.target).norm() == 0 ||
        v.up.norm() == 0) {
      return make_error(ErrorCode::kInvalidArgument, source + ": section " + sections::kView +
                                                         " should hold a finite eye ≠ target, an up ≠ 0 and a field "
                                                         "of view in (0, π)");
    }
    setup.view = v;
  }
  auto samples = in.metadata_int(kSamplesKey);
  if (!samples) return named(samples.error(), source);
  setup.gather.samples = *samples;
  const std::string seed = in.metadata_value(kSeedKey, "0");
  try {
    size_t used = 0;
    setup.gather.seed = std::stoull(seed, &used);
    if (used != seed.size()) throw std::invalid_argument(seed);
  } catch (const std::exception&) {
    return make_error(ErrorCode::kInvalidArgument, source + ": metadata " + kSeedKey + " should be an unsigned integer, got '" + seed + "'");
  }
  const std::string sampling = in.metadata_value(kSamplingKey, "hammersley");
  if (sampling == "stratified") {
    setup.gather.sampling = HemisphereSampling::kStratified;
  } else if (sampling != "hammersley") {
    return make_error(ErrorCode::kInvalidArgument, source + ": metadata " + kSamplingKey +
                                                       " should be 'hammersley' or 'stratified', got '" + sampling + "'");
  }
  if (in.metadata().count(kLightRadiusKey) != 0) {
    const std::string radius = in.metadata_value(kLightRadiusKey);
    char* end = nullptr;
    setup.gather.light_radius = std::strtod(radius.c_str(), &end);
    if (radius.empty() || end != radius.c_str() + radius.size()) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata " + kLightRadiusKey + " should be a number, got '" + radius + "'");
    }
    auto rays = in.metadata_int(kShadowRaysKey);
    if (!rays) return named(rays.error(), source);
    setup.gather.shadow_rays = *rays;
  }
  auto from_vertices = read_marker(in, kDirectAtHitsKey, "vertices", "shadow rays", source);
  if (!from_vertices) return from_vertices.error();
  setup.gather.direct_from_vertices = *from_vertices;
  auto cell_average = read_marker(in, kRayOriginsKey, "cell", "vertex", source);
  if (!cell_average) return cell_average.error();
  setup.gather.cell_average = *cell_average;
  if (in.metadata().count(kCellShadowRaysKey) != 0) {
    auto rays = in.metadata_int(kCellShadowRaysKey);
    if (!rays) return named(rays.error(), source);
    setup.gather.cell_shadow_rays = *rays;
  }
  Status gather = check_gather_options(setup.gather);
  if (!gather.ok()) return named(gather.error(), source);
  if (in.metadata().count(kFilterNeighboursKey) != 0) {
    auto neighbours = in.metadata_int(kFilterNeighboursKey);
    if (!neighbours) return named(neighbours.error(), source);
    setup.filter.neighbours = *neighbours;
    const std::string cosine = in.metadata_value(kFilterNormalKey, "0.9");
    char* end = nullptr;
    setup.filter.min_normal_cosine = std::strtod(cosine.c_str(), &end);
    if (cosine.empty() || end != cosine.c_str() + cosine.size()) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata " + kFilterNormalKey + " should be a number, got '" + cosine + "'");
    }
    const std::string linear = in.metadata_value(kFilterLinearKey, "false");
    if (linear != "true" && linear != "false") {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata " + kFilterLinearKey + " should be 'true' or 'false', got '" + linear + "'");
    }
    setup.filter.linear = linear == "true";
    if (setup.filter.neighbours < 0 || !(setup.filter.min_normal_cosine > -1 && setup.filter.min_normal_cosine <= 1)) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": metadata " + kFilterNeighboursKey + " should be ≥ 0 and " + kFilterNormalKey +
                            " in (−1, 1], got " + std::to_string(setup.filter.neighbours) + " and " + cosine);
    }
  }
  if (in.metadata().count(kKeySamplesKey) != 0) {
    auto key_samples = in.metadata_int(kKeySamplesKey);
    if (!key_samples) return named(key_samples.error(), source);
    if (*key_samples < 1) {
      return make_error(ErrorCode::kInvalidArgument, source + ": metadata " + kKeySamplesKey + " should be ≥ 1, got " +
                                                         std::to_string(*key_samples));
    }
    setup.key_samples = *key_samples;
  }
  setup.quantity = in.metadata_value(kQuantityKey, "indirect");
  if (setup.quantity != "indirect") {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": metadata " + kQuantityKey + " should be 'indirect', got '" + setup.quantity + "'");
  }
  return setup;
}

}  // namespace animspace::illumination

namespace animspace::illumination {

Result<ServedIllumination> load_served_illumination(const container::ModelContainer& in, const std::string& source) {
  auto setup = load_illumination(in, source);
  if (!setup) return setup.error();
  ServedIllumination served;
  served.gather = setup->gather;
  served.key_gather = setup->gather;
  if (setup->key_samples > 0) served.key_gather.samples = setup->key_samples;
  auto filter = surface_filter_precompute(setup->surface, setup->filter, "metadata illumination.filter");
  if (!filter) return named(filter.error(), source);
  served.filter = std::make_shared<const SurfaceFilter>(std::move(*filter));
  served.training_lights = std::move(setup->training_lights);
  served.view = setup->view;
  const std::string scale = in.metadata_value("illumination.radiance_scale", "0");
  char* end = nullptr;
  served.radiance_scale = std::strtod(scale.c_str(), &end);
  if (end == scale.c_str() || *end != '\0' || !std::isfinite(served.radiance_scale) || served.radiance_scale < 0) {
    return make_error(ErrorCode::kInvalidArgument, source + ": metadata illumination.radiance_scale should be a finite "
                                                            "number ≥ 0, got '" + scale + "'");
  }
  auto engine = IlluminationEngine::create(std::move(setup->surface));
  if (!engine) return named(engine.error(), source);
  served.engine = std::move(*engine);
  return served;
}

void ServedIllumination::full(const std::vector<PointLight>& lights, Eigen::VectorXf& out) const {
  if (filter == nullptr || !filter->enabled()) {
    engine->indirect(lights, gather, engine->all_points(), out);
    return;
  }
  Eigen::VectorXf gathered;
  engine->indirect(lights, gather, engine->all_points(), gathered);
  surface_filter_apply(*filter, gathered, out);
}

void ServedIllumination::keys(const std::vector<PointLight>& lights, const std::vector<int>& points,
                              Eigen::VectorXf& out) const {
  gather_keys(*engine, gather, filter.get(), key_gather.samples != gather.samples ? key_gather.samples : 0, lights,
              points, out);
}

void gather_keys(const IlluminationEngine& engine, const GatherOptions& gather, const SurfaceFilter* filter,
                 int key_samples, const std::vector<PointLight>& lights, const std::vector<int>& points,
                 Eigen::VectorXf& out) {
  if (key_samples > 0) {
    GatherOptions keys = gather;
    keys.samples = key_samples;
    engine.indirect(lights, keys, points, out);
    return;
  }
  if (filter == nullptr || !filter->enabled()) {
    engine.indirect(lights, gather, points, out);
    return;
  }
  const std::vector<int> support = surface_filter_support(*filter, points);
  Eigen::VectorXf values;
  engine.indirect(lights, gather, support, values);
  surface_filter_apply_at(*filter, points, support, values, out);
}

}  // namespace animspace::illumination
