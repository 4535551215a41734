// The illumination model: the engine's sections round-trip through a container, and a PMSC model
// trained on gathered frames reproduces its training frames from their key points — and is served
// with its engine (model::load_servable).
#include <cmath>

#include <gtest/gtest.h>

#include "core/container/model_container.h"
#include "core/illumination/illumination_io.h"
#include "core/illumination/illumination_model.h"
#include "core/model/servable.h"
#include "core/pmsc/pmsc_io.h"

namespace animspace::illumination {
namespace {

IlluminationSetup small_setup() {
  IlluminationSetup setup;
  setup.surface = cornell_box({1500});
  setup.gather.samples = 8;
  setup.gather.seed = 7;
  setup.training_lights = {{{0.1, 0.5, 0.2}, {1, 2, 3}}, {{0.3, 0.5, 0.4}, {0.5, 0.5, 0.5}}};
  setup.view = cornell_view();
  return setup;
}

TEST(IlluminationIoTest, SetupRoundTripsThroughAContainer) {
  const IlluminationSetup setup = small_setup();
  container::ModelContainer out;
  attach_illumination(out, setup);
  ASSERT_TRUE(has_illumination(out));
  auto parsed = container::parse(container::serialize(out), "mem");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  auto loaded = load_illumination(*parsed, "mem");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->surface.vertices, setup.surface.vertices);
  EXPECT_EQ(loaded->surface.normals, setup.surface.normals);
  EXPECT_EQ(loaded->surface.albedo, setup.surface.albedo);
  EXPECT_EQ(loaded->surface.faces, setup.surface.faces);
  EXPECT_EQ(loaded->gather.samples, 8);
  EXPECT_EQ(loaded->gather.seed, 7u);
  ASSERT_EQ(loaded->training_lights.size(), 2u);
  EXPECT_EQ(loaded->training_lights[1].position, setup.training_lights[1].position);
  EXPECT_EQ(loaded->training_lights[0].intensity, setup.training_lights[0].intensity);
  EXPECT_EQ(loaded->quantity, "indirect");
  ASSERT_TRUE(loaded->view.has_value());
  EXPECT_EQ(loaded->view->target, setup.view->target);
  EXPECT_EQ(loaded->view->vertical_fov_rad, setup.view->vertical_fov_rad);
}

// Issue #38: the gather's sampling and disc lights round-trip; a file without them (every file
// written before) loads as the original gather, Hammersley with point lights.
TEST(IlluminationIoTest, GatherChoicesRoundTripAndOlderFilesLoadAsTheOriginalGather) {
  IlluminationSetup setup = small_setup();
  container::ModelContainer original;
  attach_illumination(original, setup);
  EXPECT_EQ(original.metadata().count("illumination.sampling"), 0u);
  EXPECT_EQ(original.metadata().count("illumination.light_radius"), 0u);
  auto loaded = load_illumination(original, "mem");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->gather.sampling, HemisphereSampling::kHammersley);
  EXPECT_EQ(loaded->gather.light_radius, 0.0);
  EXPECT_EQ(loaded->gather.shadow_rays, 1);

  setup.gather.sampling = HemisphereSampling::kStratified;
  setup.gather.light_radius = 0.015;
  setup.gather.shadow_rays = 3;
  container::ModelContainer out;
  attach_illumination(out, setup);
  auto parsed = container::parse(container::serialize(out), "mem");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  loaded = load_illumination(*parsed, "mem");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->gather.sampling, HemisphereSampling::kStratified);
  EXPECT_EQ(loaded->gather.light_radius, 0.015);
  EXPECT_EQ(loaded->gather.shadow_rays, 3);

  out.metadata()["illumination.sampling"] = "sobol";
  auto refused = load_illumination(out, "mem");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("illumination.sampling"), std::string::npos) << refused.error().message;
}

// Issue #38 item 1: the surface filter and the key points' rays round-trip; a file without them
// (every file written before) loads unfiltered with the keys gathered as the frames were, and the
// served engine's full calculation and key gather are the gather (+ filter) computed directly.
TEST(IlluminationIoTest, FilterAndKeySamplesRoundTripAndOlderFilesLoadUnfiltered) {
  IlluminationSetup setup = small_setup();
  container::ModelContainer original;
  attach_illumination(original, setup);
  EXPECT_EQ(original.metadata().count("illumination.filter_neighbours"), 0u);
  EXPECT_EQ(original.metadata().count("illumination.key_samples"), 0u);
  auto older = load_served_illumination(original, "mem");
  ASSERT_TRUE(older.ok()) << older.error().message;
  ASSERT_TRUE(older->filter != nullptr);
  EXPECT_FALSE(older->filter->enabled());
  EXPECT_EQ(older->key_gather.samples, 8);
  const std::vector<PointLight> light{{{0.25, 0.4, 0.3}, {1, 1, 1}}};
  Eigen::VectorXf served, direct;
  older->full(light, served);
  older->engine->indirect(light, setup.gather, older->engine->all_points(), direct);
  EXPECT_EQ(served, direct) << "an older file's full calculation is the gather as it was";

  setup.filter = {24, 0.85, true};
  setup.key_samples = 32;
  container::ModelContainer out;
  attach_illumination(out, setup);
  auto parsed = container::parse(container::serialize(out), "mem");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  auto loaded = load_illumination(*parsed, "mem");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->filter.neighbours, 24);
  EXPECT_EQ(loaded->filter.min_normal_cosine, 0.85);
  EXPECT_TRUE(loaded->filter.linear);
  EXPECT_EQ(loaded->key_samples, 32);
  auto filtered = load_served_illumination(*parsed, "mem");
  ASSERT_TRUE(filtered.ok()) << filtered.error().message;
  ASSERT_TRUE(filtered->filter != nullptr && filtered->filter->enabled());
  EXPECT_EQ(filtered->key_gather.samples, 32);
  EXPECT_EQ(filtered->gather.samples, 8);
  auto filter = surface_filter_precompute(setup.surface, {24, 0.85, true});
  ASSERT_TRUE(filter.ok());
  Eigen::VectorXf expected;
  surface_filter_apply(*filter, direct, expected);
  filtered->full(light, served);
  EXPECT_EQ(served, expected) << "the served full calculation filters the same gather";
  EXPECT_NE(served, direct);
  const std::vector<int> keys{3, 500, 1200};
  Eigen::VectorXf key_values, key_direct;
  filtered->keys(light, keys, key_values);
  GatherOptions key_gather = setup.gather;
  key_gather.samples = 32;
  filtered->engine->indirect(light, key_gather, keys, key_direct);
  EXPECT_EQ(key_values, key_direct) << "the keys are gathered with key_samples rays";
  // Without key_samples the keys are the full calculation's values at the key points: the gather
  // at their filters' support, filtered there.
  Eigen::VectorXf from_support;
  gather_keys(*filtered->engine, setup.gather, filtered->filter.get(), 0, light, keys, from_support);
  for (size_t p = 0; p < keys.size(); ++p) {
    EXPECT_EQ(Eigen::Vector3f(from_support.segment<3>(3 * static_cast<long>(p))),
              Eigen::Vector3f(expected.segment<3>(3 * keys[p])))
        << "key " << keys[p];
  }

  for (const auto& [key, value] : std::vector<std::pair<std::string, std::string>>{
           {"illumination.filter_neighbours", "-2"},
           {"illumination.filter_min_normal_cosine", "1.5"},
           {"illumination.filter_min_normal_cosine", "much"},
           {"illumination.filter_linear", "yes"},
           {"illumination.key_samples", "0"}}) {
    container::ModelContainer bad = *parsed;
    bad.metadata()[key] = value;
    auto refused = load_illumination(bad, "m.anim");
    ASSERT_FALSE(refused.ok()) << key << " = " << value;
    EXPECT_NE(refused.error().message.find(key), std::string::npos) << refused.error().message;
    EXPECT_NE(refused.error().message.find("m.anim"), std::string::npos) << refused.error().message;
  }
}

TEST(IlluminationIoTest, RefusesSectionsThatDisagreeNamingThem) {
  const IlluminationSetup setup = small_setup();
  container::ModelContainer out;
  attach_illumination(out, setup);
  out.set_points(sections::kAlbedo, setup.surface.albedo.topRows(3));
  auto loaded = load_illumination(out, "m.anim");
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("m.anim"), std::string::npos);
  EXPECT_NE(loaded.error().message.find(sections::kAlbedo), std::string::npos);

  container::ModelContainer bad_samples;
  attach_illumination(bad_samples, setup);
  bad_samples.metadata()["illumination.samples"] = "0";
  auto refused = load_illumination(bad_samples, "m.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("samples"), std::string::npos);

  container::ModelContainer bad_quantity;
  attach_illumination(bad_quantity, setup);
  bad_quantity.metadata()["illumination.quantity"] = "caustics";
  EXPECT_FALSE(load_illumination(bad_quantity, "m.anim").ok());
}

// Issue #38: a gather choice stored as `key` = `marker` only when made. A file without the key
// (every file before it) loads with the other choice; the marker reads back; another value is
// refused naming the file, the key and the value. Returns the file with the marker.
container::ModelContainer expect_marker_round_trips(const std::string& key, const std::string& marker,
                                                    const std::string& unknown, bool GatherOptions::*choice) {
  IlluminationSetup setup = small_setup();
  EXPECT_FALSE(setup.gather.*choice);
  container::ModelContainer older;
  attach_illumination(older, setup);
  EXPECT_EQ(older.metadata().count(key), 0u) << "unchanged files for older readers";
  auto loaded = load_illumination(older, "old.anim");
  EXPECT_TRUE(loaded.ok()) << loaded.error().message;
  if (loaded.ok()) {
    EXPECT_FALSE((*loaded).gather.*choice);
  }

  setup.gather.*choice = true;
  container::ModelContainer out;
  attach_illumination(out, setup);
  EXPECT_EQ(out.metadata_value(key), marker);
  loaded = load_illumination(out, "m.anim");
  EXPECT_TRUE(loaded.ok()) << loaded.error().message;
  if (loaded.ok()) {
    EXPECT_TRUE((*loaded).gather.*choice);
  }

  container::ModelContainer bad = out;
  bad.metadata()[key] = unknown;
  auto refused = load_illumination(bad, "m.anim");
  EXPECT_FALSE(refused.ok());
  if (!refused.ok()) {
    for (const std::string& named : {key, unknown, std::string("m.anim")}) {
      EXPECT_NE(refused.error().message.find(named), std::string::npos) << refused.error().message;
    }
  }
  return out;
}

// The cell-averaged gather: illumination.ray_origins = cell; older files read as rays from the vertices.
TEST(IlluminationIoTest, TheCellAverageRoundTripsAndOlderFilesReadAsRaysFromTheVertices) {
  expect_marker_round_trips("illumination.ray_origins", "cell", "centroid", &GatherOptions::cell_average);
}

// The direct light read from the vertices: illumination.direct_at_hits = vertices; older files
// read as a shadow ray per hit; the key beside a disc light is refused naming the field.
TEST(IlluminationIoTest, TheDirectLightAtTheHitsRoundTripsAndOlderFilesReadAsShadowRays) {
  const container::ModelContainer out = expect_marker_round_trips(
      "illumination.direct_at_hits", "vertices", "photons", &GatherOptions::direct_from_vertices);
  container::ModelContainer bad = out;
  bad.metadata()["illumination.light_radius"] = "0.01";
  bad.metadata()["illumination.shadow_rays"] = "2";
  auto refused = load_illumination(bad, "m.anim");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("light_radius"), std::string::npos) << refused.error().message;
}

// The cell's shadow rays: illumination.cell_shadow_rays = K only when K > 0, so that older files
// (and the vertex's own shadow ray) read as 0; K reads back; a value that is not a count, or a
// count without the direct light read from the vertices, is refused naming the file and the key.
TEST(IlluminationIoTest, TheCellShadowRaysRoundTripAndOlderFilesReadAsTheVertexsOwnRay) {
  IlluminationSetup setup = small_setup();
  setup.gather.direct_from_vertices = true;
  container::ModelContainer older;
  attach_illumination(older, setup);
  EXPECT_EQ(older.metadata().count("illumination.cell_shadow_rays"), 0u) << "unchanged files for older readers";
  auto loaded = load_illumination(older, "old.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->gather.cell_shadow_rays, 0);

  setup.gather.cell_shadow_rays = 24;
  container::ModelContainer out;
  attach_illumination(out, setup);
  EXPECT_EQ(out.metadata_value("illumination.cell_shadow_rays"), "24");
  auto parsed = container::parse(container::serialize(out), "mem");
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  loaded = load_illumination(*parsed, "m.anim");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->gather.cell_shadow_rays, 24);

  for (const auto& [value, without_vertices] : {std::pair{"many", false}, std::pair{"-2", false}, std::pair{"8", true}}) {
    container::ModelContainer bad = out;
    bad.metadata()["illumination.cell_shadow_rays"] = value;
    if (without_vertices) bad.metadata().erase("illumination.direct_at_hits");
    auto refused = load_illumination(bad, "m.anim");
    ASSERT_FALSE(refused.ok()) << value;
    for (const std::string& named : {std::string("m.anim"), std::string("cell_shadow_rays")}) {
      EXPECT_NE(refused.error().message.find(named), std::string::npos) << refused.error().message;
    }
  }
}

// A training small enough for a unit test: 25 lights under the ceiling, 8 rays (the direct light
// read from the vertices, the default), 60 keys.
IlluminationTrainingOptions small_training() {
  IlluminationTrainingOptions options;
  for (const Eigen::Vector3d& p : light_grid(cornell_room(), {5, 5, 0.05, 0.1})) {
    options.lights.push_back({p, Eigen::Vector3d::Ones()});
  }
  options.gather.samples = 8;
  options.pmsc.max_key_points = 60;
  options.pmsc.region_count = 2;
  options.filter.neighbours = 0;  // the raw gather; TrainsOnFilteredFrames… tests the filter
  return options;
}

TEST(IlluminationModelTest, RadianceScaleIsTheMedianFrameMaximum) {
  FrameMatrix frames(3, 6);
  // Point norms: frame 0 → {5, 1}, frame 1 → {0, 13}, frame 2 → {2, 0}: maxima 5, 13, 2.
  frames << 3, 4, 0, 1, 0, 0,  //
      0, 0, 0, 5, 12, 0,       //
      0, 0, 2, 0, 0, 0;
  EXPECT_DOUBLE_EQ(radiance_scale(frames), 5.0);
  // Largest over RMS point radiance: 5 / √13, 13 / (13 / √2) = √2, 2 / (2 / √2) = √2; median √2.
  EXPECT_NEAR(peak_to_rms_ratio(frames), std::sqrt(2.0), 1e-12);
}

TEST(IlluminationModelTest, TrainedModelReproducesItsTrainingFramesAndServesWithItsEngine) {
  auto engine = IlluminationEngine::create(cornell_box({2000}));
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  IlluminationTrainingOptions options = small_training();
  IlluminationTrainingReport report;
  auto model_file = train_illumination(**engine, options, "test", &report);
  ASSERT_TRUE(model_file.ok()) << model_file.error().message;
  EXPECT_GT(report.radiance_scale, 0);

  auto servable = model::load_servable(*model_file, "trained");
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  ASSERT_TRUE(servable->pmsc && servable->illumination && servable->illumination->engine);
  EXPECT_EQ(servable->info.fail_through, model::FailThrough::kServer);
  EXPECT_EQ(servable->info.server_engine, model::ServerEngine::kIllumination);
  EXPECT_EQ(servable->info.channel_count, 3);
  EXPECT_EQ(servable->illumination->gather.samples, 8);
  EXPECT_TRUE(servable->illumination->gather.direct_from_vertices) << "the training's default gather, stored";
  ASSERT_EQ(servable->illumination->training_lights.size(), options.lights.size());
  EXPECT_NEAR(servable->illumination->radiance_scale, report.radiance_scale, 1e-6 * report.radiance_scale);
  ASSERT_TRUE(servable->illumination->view.has_value());
  EXPECT_EQ(servable->illumination->view->eye, cornell_view().eye);
  const pmsc::PmscModel& model = *servable->pmsc;

  // Each training frame, gathered again at its key points only (the engine is deterministic per
  // point), is reconstructed within the trainer's reported training error.
  const std::vector<int> all = (*engine)->all_points();
  for (size_t f = 0; f < options.lights.size(); ++f) {
    Eigen::VectorXf full, keys;
    (*engine)->indirect({options.lights[f]}, options.gather, all, full);
    (*engine)->indirect({options.lights[f]}, options.gather, model.key_points, keys);
    ASSERT_EQ(keys, pmsc::gather_key_values(model, full)) << "light " << f;
    pmsc::CachedPose cached;
    pmsc::evaluate_cached(model, keys, nullptr, cached);
    const Eigen::VectorXf difference = cached.points - full;
    const Eigen::Map<const Eigen::Matrix3Xf> error(difference.data(), 3, model.point_count);
    EXPECT_LE(error.colwise().norm().maxCoeff(), report.pmsc.max_training_error * 1.001 + 1e-6) << "light " << f;
  }
}

// Issue #38 item 1: a model trained on filtered frames stores its filter and key rays, and its
// served full calculation is the filtered gather; bad values are refused naming the field.
TEST(IlluminationModelTest, TrainsOnFilteredFramesAndServesTheSameFilter) {
  auto engine = IlluminationEngine::create(cornell_box({1500}));
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  IlluminationTrainingOptions options = small_training();
  options.filter = {16, 0.9};
  options.key_samples = 32;
  IlluminationTrainingReport report;
  auto model_file = train_illumination(**engine, options, "test", &report);
  ASSERT_TRUE(model_file.ok()) << model_file.error().message;
  EXPECT_EQ(model_file->metadata_value("illumination.filter_neighbours"), "16");
  EXPECT_EQ(model_file->metadata_value("illumination.key_samples"), "32");
  auto servable = model::load_servable(*model_file, "trained");
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  const pmsc::PmscModel& model = *servable->pmsc;

  // Training frame 0, gathered and filtered directly: the served full calculation is that frame,
  // and the model reproduces it from its own key values within the reported training error.
  auto filter = surface_filter_precompute((*engine)->surface(), options.filter);
  ASSERT_TRUE(filter.ok());
  Eigen::VectorXf gathered, frame, served;
  (*engine)->indirect({options.lights[0]}, options.gather, (*engine)->all_points(), gathered);
  surface_filter_apply(*filter, gathered, frame);
  servable->illumination->full({options.lights[0]}, served);
  EXPECT_EQ(served, frame);
  pmsc::CachedPose cached;
  pmsc::evaluate_cached(model, pmsc::gather_key_values(model, frame), nullptr, cached);
  const Eigen::VectorXf difference = cached.points - frame;
  const Eigen::Map<const Eigen::Matrix3Xf> error(difference.data(), 3, model.point_count);
  EXPECT_LE(error.colwise().norm().maxCoeff(), report.pmsc.max_training_error * 1.001 + 1e-6);

  IlluminationTrainingOptions bad = small_training();
  bad.filter.neighbours = -4;
  auto refused = train_illumination(**engine, bad, "test", nullptr);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("filter.neighbours"), std::string::npos) << refused.error().message;
  bad = small_training();
  bad.key_samples = -1;
  refused = train_illumination(**engine, bad, "test", nullptr);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("key_samples"), std::string::npos) << refused.error().message;
}

TEST(IlluminationModelTest, ADimAndABrightLightGetTheSameVerdict) {
  // Issue #38 item 2: the tolerance is relative to each frame's radiance, so the verdict on a
  // light does not depend on its intensity. The gather is linear in the intensity; the keys of a
  // light ten times brighter are ten times the keys, and every error is measured against S.
  auto engine = IlluminationEngine::create(cornell_box({1500}));
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  IlluminationTrainingOptions options = small_training();
  ASSERT_TRUE(options.relative_tolerance) << "the default since issue #38";
  IlluminationTrainingReport report;
  auto model_file = train_illumination(**engine, options, "test", &report);
  ASSERT_TRUE(model_file.ok()) << model_file.error().message;
  EXPECT_GT(report.peak_to_rms_ratio, 1) << "a frame's largest radiance is above its RMS";
  auto servable = model::load_servable(*model_file, "trained");
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  const pmsc::PmscModel& model = *servable->pmsc;
  ASSERT_TRUE(model.relative_tolerance);

  // Lights between the training lights and off the grid's plane.
  const Box room = cornell_room();
  for (int l = 0; l < 6; ++l) {
    const Eigen::Vector3d position = room.min + Eigen::Vector3d(0.2 + 0.12 * l, 0.9 - 0.08 * l, 0.3 + 0.07 * l)
                                                    .cwiseProduct(room.max - room.min);
    Eigen::VectorXf dim_keys, bright_keys, dim_checks, bright_checks;
    (*engine)->indirect({{position, Eigen::Vector3d::Constant(0.2)}}, options.gather, model.key_points, dim_keys);
    (*engine)->indirect({{position, Eigen::Vector3d::Constant(20.0)}}, options.gather, model.key_points, bright_keys);
    (*engine)->indirect({{position, Eigen::Vector3d::Constant(0.2)}}, options.gather, model.check_points, dim_checks);
    (*engine)->indirect({{position, Eigen::Vector3d::Constant(20.0)}}, options.gather, model.check_points,
                        bright_checks);
    ASSERT_LE((bright_keys - 100.0f * dim_keys).cwiseAbs().maxCoeff(), 1e-4f * bright_keys.cwiseAbs().maxCoeff())
        << "the gather is linear in the light's intensity";
    pmsc::PoseEstimate dim, bright;
    pmsc::estimate_coordinates(model, dim_keys, dim_checks, dim);
    pmsc::estimate_coordinates(model, bright_keys, bright_checks, bright);
    const auto dim_status = pmsc::decide(dim.error_estimate, pmsc::verdict_thresholds(model, dim)).status;
    EXPECT_EQ(pmsc::decide(bright.error_estimate, pmsc::verdict_thresholds(model, bright)).status, dim_status)
        << "light " << l << ": e = " << dim.error_estimate << " and " << bright.error_estimate;
    if (dim.scale == 0) {  // a light inside a block reaches no key point: nothing to be relative to
      EXPECT_EQ(bright.scale, 0) << "light " << l;
      EXPECT_EQ(dim_status, pmsc::CacheStatus::kMiss) << "light " << l;
      continue;
    }
    EXPECT_NEAR(bright.error_estimate, dim.error_estimate, 1e-3 * dim.error_estimate) << "light " << l;
    EXPECT_NEAR(bright.scale, 100 * dim.scale, 1e-3 * bright.scale) << "light " << l;
  }
}

}  // namespace
}  // namespace animspace::illumination
