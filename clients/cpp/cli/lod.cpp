#include "clients/cpp/cli/lod.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <optional>
#include <sstream>
#include <vector>

#include "clients/cpp/cli/offline_common.h"
#include "clients/cpp/cli/output.h"
#include "clients/cpp/tools/number_checks.h"
#include "clients/cpp/tools/pose_file.h"
#include "core/animspace/animspace_io.h"
#include "core/atlas/atlas_io.h"
#include "core/common/atomic_file.h"
#include "core/common/format.h"
#include "core/mesh_io/posed_mesh.h"
#include "core/lod/lod_io.h"
#include "core/lod/selection.h"
#include "core/lod/levels.h"
#include "core/container/sections.h"
#include "core/geometry/normals.h"

namespace animspace::cli {

namespace as = animation_space;

CLI::App* add_build_lod(CLI::App& app, BuildLodArgs& a) {
  auto* cmd = app.add_subcommand(
      "build-lod",
      "Offline: add levels of detail to an animation-space model — memoryless appearance-preserving simplification "
      "in animation space (Merry 2007 ch. 6), levels halving the influences (§7.3), each level's vertices placed to "
      "fit the model across poses, then its influences simplified while the error they add pays for itself; a model "
      "with a texture atlas keeps its chart borders and every level carries its UVs — and write a model version");
  cmd->add_option("input", a.input, "An animation-space model.anim (from fit or import-rig)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_flag("--no-influence-simplification", a.no_influence_simplification,
                "Edge collapses only (no §6.3 influence removals)");
  cmd->add_flag("--no-placement", a.no_placement,
                "Keep every level's vertices where the input had them (no fit across poses; ε^l is then the "
                "largest step's deviation, and influences are removed in the progressive mesh's own order, §6.3.1)");
  cmd->add_option("--influence-exchange", a.influence_exchange,
                  "Placed levels: the fraction of RMS error a level may gain per fraction of its influences removed "
                  "(0: only removals that cost nothing)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  cmd->add_option("--max-levels", a.max_levels, "Levels to keep, level 0 included")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--max-normal-deviation", a.max_normal_deviation_degrees,
                  "Refuse collapses that turn a face by more than this (degrees, rest pose)")
      ->check(CLI::Range(1.0, 180.0))
      ->capture_default_str();
  add_sample_pose_options(cmd, a.poses);
  add_model_output_options(cmd, a.output, a.model, a.version);
  return cmd;
}

int run_build_lod(const BuildLodArgs& a, bool json) {
  auto in = container::read_file(a.input);
  if (!in) return fail("build-lod", in.error().message);
  auto model = as::load(*in, a.input);
  if (!model) return fail("build-lod", model.error().message);
  container::ModelContainer out = *in;
  auto stored = model_metrics(*in, *model, a.poses, a.input, out);
  if (!stored) return fail("build-lod", stored.error().message);
  lod::LevelBuildOptions options;
  options.influence_simplification = !a.no_influence_simplification;
  options.placement = !a.no_placement;
  options.influence_exchange = a.influence_exchange;
  options.max_levels = a.max_levels;
  options.max_normal_deviation_degrees = a.max_normal_deviation_degrees;
  // A model with an atlas (animspace atlas): the levels keep its chart borders and carry its UVs
  // (lod/chart_atlas.h).
  auto stored_atlas = atlas::load_atlas(*in, model->faces.rows(), a.input);
  if (!stored_atlas) return fail("build-lod", stored_atlas.error().message);
  std::optional<lod::ChartAtlas> charts;
  if (*stored_atlas) charts = lod::ChartAtlas{(*stored_atlas)->chart_of_face, (*stored_atlas)->uvs};
  options.atlas = charts ? &*charts : nullptr;
  options.progress = progress_bars("build-lod");
  const auto start = std::chrono::steady_clock::now();
  auto built = lod::build_levels(*model, stored->metrics, options);
  options.progress = nullptr;  // ends the bar's line before the report
  if (!built) return fail("build-lod", built.error().message);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const lod::LodLevels& levels = built->lods;
  lod::store_levels(levels, out);
  out.metadata()["lod.influence_simplification"] =
      !options.influence_simplification ? "false"
      : options.placement               ? "after placement, exchange " + format_number(options.influence_exchange)
                                        : "true";
  out.metadata()["lod.placement"] = a.no_placement ? "none" : "fitted";
  const auto path = model_output_path(a.output, a.model, a.version);
  if (auto written = write_model_file(path, out); !written.ok()) return fail("build-lod", written.error().message);

  // Per level, the trade-off a user picks from: vertices, influences and error, and (placed) the
  // same level with edge collapses only — what its influence simplification gave and cost.
  const auto fit_of = [&](int l) -> const lod::LevelFit* {
    return built->fits.empty() ? nullptr : &built->fits[static_cast<size_t>(l)];
  };
  if (json) {
    nlohmann::json rows = nlohmann::json::array();
    for (int l = 0; l < levels.count(); ++l) {
      const lod::LodLevel& level = levels.levels[static_cast<size_t>(l)];
      nlohmann::json row = {{"level", l},
                            {"vertices", level.model.vertex_count()},
                            {"faces", level.model.faces.rows()},
                            {"influences", level.model.influences.influence_count()},
                            {"epsilon", level.epsilon}};
      if (const lod::LevelFit* fit = fit_of(l)) {
        row["rms_error"] = fit->rms;
        row["collapses_only"] = {{"influences", fit->influences_before}, {"rms_error", fit->rms_before}};
      }
      rows.push_back(std::move(row));
    }
    print_json({{"output", path.string()},
                {"seconds", seconds},
                {"steps", built->steps},
                {"chart_borders", charts.has_value()},
                {"levels", rows}});
  } else {
    if (charts) std::printf("the atlas's chart borders kept; every level carries its UVs\n");
    std::printf("progressive mesh: %zu steps; levels built in %.2f s\n%6s %9s %9s %11s %12s %12s %26s\n", built->steps,
                seconds, "level", "vertices", "faces", "influences", "ε^l", "RMS", "collapses only: infl, RMS");
    for (int l = 0; l < levels.count(); ++l) {
      const lod::LodLevel& level = levels.levels[static_cast<size_t>(l)];
      std::printf("%6d %9d %9d %11d %12.4g", l, level.model.vertex_count(), static_cast<int>(level.model.faces.rows()),
                  level.model.influences.influence_count(), level.epsilon);
      if (const lod::LevelFit* fit = fit_of(l)) {
        std::printf(" %12.4g %13d %12.4g", fit->rms, fit->influences_before, fit->rms_before);
      }
      std::printf("\n");
    }
    std::printf("wrote %s\n", path.c_str());
    print_serving_hint(a.model);
  }
  return 0;
}

CLI::App* add_export_lod(CLI::App& app, ExportLodArgs& a) {
  auto* cmd = app.add_subcommand(
      "export-lod",
      "Offline: write one level of detail of an animation-space model, posed, as OBJ, PLY or glTF 2.0 (.glb/.gltf), "
      "ordered for the vertex cache (meshoptimizer); the level is given or chosen for a view by eq. 7.2");
  cmd->add_option("input", a.input, "An animation-space model.anim with levels (build-lod)")
      ->required()
      ->check(CLI::ExistingFile);
  auto* level = cmd->add_option("--level", a.level, "Level to write (0 = full detail)")->check(tools::kNonNegative);
  auto* tolerance = cmd->add_option("--tolerance-px", a.tolerance_px, "Pixel error tolerance p (eq. 7.2)")
                        ->check(tools::kPositive);
  cmd->add_option("--distance", a.distance,
                  "With --tolerance-px: camera distance to the model's bounding-sphere centre, model units")
      ->check(tools::kPositive)
      ->needs(tolerance);
  cmd->add_option("--fov-deg,--fov", a.fov_degrees,
                  "With --tolerance-px: horizontal field of view 2θ in DEGREES (the API's horizontal_fov_rad is "
                  "radians; the command line converts)")
      ->check(CLI::Range(1.0, 179.0))
      ->capture_default_str()
      ->needs(tolerance);
  cmd->add_option("--width", a.viewport_width_px, "With --tolerance-px: viewport width w, pixels")
      ->check(tools::kPositive)
      ->capture_default_str()
      ->needs(tolerance);
  cmd->add_option("--frame", a.frame, "Pose: the model's stored training frame K (default: the rest pose)")
      ->check(tools::kNonNegative);
  cmd->add_option("-o,--output", a.output, "Output mesh: .obj, .ply, .glb or .gltf")->required();
  level->excludes(tolerance);
  return cmd;
}

int run_export_lod(const ExportLodArgs& a, bool json) {
  if (const std::string bad =
          check_output_extension(a.output, {".obj", ".ply", ".glb", ".gltf"}, "export-lod writes a mesh");
      !bad.empty()) {
    return fail("export-lod", bad);
  }
  auto in = container::read_file(a.input);
  if (!in) return fail("export-lod", in.error().message);
  auto model = as::load(*in, a.input);
  if (!model) return fail("export-lod", model.error().message);
  auto levels = lod::load_levels(*in, *model, a.input);
  if (!levels) return fail("export-lod", levels.error().message);

  int chosen = 0;
  double tolerated = 0;
  if (a.level >= 0) {
    if (a.level >= levels->count()) {
      return fail("export-lod",
                  "--level: expected 0 … " + std::to_string(levels->count() - 1) + ", got " + std::to_string(a.level));
    }
    chosen = a.level;
  } else if (a.tolerance_px > 0) {
    if (a.distance <= 0) return fail("export-lod", "--tolerance-px needs --distance (camera to the model)");
    auto sphere = lod::model_bounding_sphere(*in, *model, a.input);
    if (!sphere) return fail("export-lod", sphere.error().message);
    lod::PixelTolerance view;
    view.tolerance_px = a.tolerance_px;
    view.viewport_width_px = a.viewport_width_px;
    view.horizontal_fov_rad = a.fov_degrees * std::numbers::pi / 180;
    view.distance = a.distance;
    auto choice = lod::level_for_view(*levels, view, sphere->radius);
    if (!choice) return fail("export-lod", choice.error().message);
    chosen = choice->level;
    tolerated = choice->tolerated_error;
  }
  const lod::LodLevel& level = levels->levels[static_cast<size_t>(chosen)];

  as::TransformList pose = model->skeleton.rest;
  if (a.frame >= 0) {
    auto rows = in->double_matrix(container::sections::kSequenceBoneTransforms, 16 * model->bone_count());
    if (!rows) return fail("export-lod", rows.error().message);
    if (a.frame >= rows->rows()) {
      return fail("export-lod",
                  "--frame: expected 0 … " + std::to_string(rows->rows() - 1) + ", got " + std::to_string(a.frame));
    }
    pose = as::pose_from_row(*rows, a.frame, model->bone_count());
  }
  mesh_io::PosedMesh mesh;
  as::evaluate(level.model, pose, mesh.points);
  mesh.faces = level.model.faces;
  // Normals from the level's tangent planes (§3.5) when it has them, else of the posed faces.
  if (level.model.has_tangents()) {
    as::evaluate_normals(level.model, pose, mesh.normals);
  } else if (mesh.faces.rows() > 0) {
    mesh.normals = geometry::area_weighted_normals(mesh.points, mesh.faces);
  }
  // The atlas (animspace atlas): level 0 carries its UVs, a coarser level those build-lod stored
  // with it (lod/chart_atlas.h); seams split.
  bool with_uvs = false;
  auto stored = atlas::load_atlas(*in, model->faces.rows(), a.input);
  if (!stored) return fail("export-lod", stored.error().message);
  if (*stored && chosen == 0) {
    mesh = mesh_io::split_seams(mesh, (*stored)->uvs.cast<float>());
    with_uvs = true;
  } else if (*stored && level.corner_uvs.rows() > 0) {
    mesh = mesh_io::split_seams(mesh, level.corner_uvs.cast<float>());
    with_uvs = true;
  }
  if (auto written = mesh_io::write_posed_mesh(a.output, mesh); !written.ok()) {
    return fail("export-lod", written.error().message);
  }
  if (json) {
    print_json({{"output", a.output},
                {"level", chosen},
                {"epsilon", level.epsilon},
                // Only a level chosen for a view (eq. 7.2) has a tolerated error.
                {"tolerated_error", a.tolerance_px > 0 ? nlohmann::json(tolerated) : nlohmann::json()},
                {"vertices", level.model.vertex_count()},
                {"faces", level.model.faces.rows()},
                {"texture_coordinates", with_uvs}});
  } else {
    char tolerated_text[48] = "";
    if (a.tolerance_px > 0) std::snprintf(tolerated_text, sizeof tolerated_text, ", tolerated %.4g", tolerated);
    std::printf("level %d of %d (ε = %.4g%s): %d vertices, %d faces%s\nwrote %s\n", chosen, levels->count(),
                level.epsilon, tolerated_text, level.model.vertex_count(), static_cast<int>(level.model.faces.rows()),
                with_uvs ? ", with the atlas's texture coordinates" : "", a.output.c_str());
  }
  return 0;
}

}  // namespace animspace::cli

namespace animspace::cli {

CLI::App* add_lod(CLI::App& app, LodArgs& a) {
  auto* cmd = app.add_subcommand(
      "lod",
      "Fetch one level of detail of a served animation-space model (LodService.GetLod), posed, and write it as "
      "OBJ, PLY or glTF 2.0 (.glb/.gltf) — the level is given, chosen for a view by eq. 7.2, or the finest within a "
      "vertex budget");
  cmd->add_option("model", a.model, "Model name")->required();
  cmd->add_option("--version", a.version, "Model version (default: the served one)");
  auto* selection = cmd->add_option_group("selection", "Which level (exactly one)");
  selection->add_option("--level", a.level, "Level (0 = full detail)")->check(tools::kNonNegative);
  auto* tolerance = selection->add_option("--tolerance-px", a.tolerance_px, "Pixel error tolerance p (eq. 7.2)")
                        ->check(tools::kPositive);
  selection->add_option("--max-vertices", a.max_vertices, "Vertex budget: the finest level within it")
      ->check(tools::kPositive);
  selection->require_option(1);
  auto* distance =
      cmd->add_option("--distance", a.distance, "With --tolerance-px: camera distance to the bounding-sphere centre")
          ->check(tools::kPositive);
  auto* fov = cmd->add_option("--fov-deg,--fov", a.fov_degrees,
                              "With --tolerance-px: horizontal field of view 2θ in DEGREES (the API's "
                              "horizontal_fov_rad is radians; the command line converts)")
                  ->check(CLI::Range(1.0, 179.0))
                  ->capture_default_str();
  auto* width = cmd->add_option("--width", a.viewport_width_px, "With --tolerance-px: viewport width w, pixels")
                    ->check(tools::kPositive)
                    ->capture_default_str();
  tolerance->needs(distance);
  // The view only matters for a pixel tolerance: given without one it would be ignored.
  for (CLI::Option* view : {distance, fov, width}) view->needs(tolerance);
  cmd->add_option("--pose-file", a.pose_file,
                  "Skeleton pose: B × 12 numbers, each bone's top three matrix rows (default: the rest pose)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--pose-space", a.pose_space, "The pose file's matrices: global G_j or local (joint) L_j")
      ->check(CLI::IsMember({"global", "local"}))
      ->capture_default_str();
  cmd->add_option("--vertices-per-chunk", a.vertices_per_chunk, "Vertices per streamed block (default: the server's)");
  cmd->add_flag("--texture-coordinates", a.texture_coordinates,
                "Fetch the model's texture atlas (animspace atlas) at the level (a coarser level's UVs as build-lod "
                "stored them under the atlas) and write it as UVs, the vertices split along its seams (OBJ vt, PLY s "
                "t, glTF TEXCOORD_0)");
  cmd->add_option("--deadline-s", a.deadline_s, "Deadline for the whole stream")
      ->check(tools::kPositive)
      ->capture_default_str();
  cmd->add_option("-o,--output", a.output, "Output mesh: .obj, .ply, .glb or .gltf")->required();
  return cmd;
}

int run_lod(const LodArgs& a, Client& client, bool json) {
  if (const std::string bad = check_output_extension(a.output, {".obj", ".ply", ".glb", ".gltf"}, "lod writes a mesh");
      !bad.empty()) {
    return fail("lod", bad);
  }
  v1::GetLodRequest request;
  request.mutable_model()->set_name(a.model);
  request.mutable_model()->set_version(a.version);
  // A render-farm node that writes a file wants the mesh as drawn: posed, not animation space.
  request.set_form(v1::GetLodRequest::FORM_POSED);
  request.set_vertices_per_chunk(a.vertices_per_chunk);
  request.set_include_texture_coordinates(a.texture_coordinates);
  if (a.level >= 0) {
    request.set_level(static_cast<uint32_t>(a.level));
  } else if (a.max_vertices > 0) {
    request.mutable_budget()->set_max_vertices(a.max_vertices);
  } else {
    auto* view = request.mutable_pixel_tolerance();
    view->set_tolerance_px(static_cast<float>(a.tolerance_px));
    view->set_distance(static_cast<float>(a.distance));
    view->set_horizontal_fov_rad(static_cast<float>(a.fov_degrees * std::numbers::pi / 180));
    view->set_viewport_width_px(a.viewport_width_px);
  }
  if (!a.pose_file.empty()) {
    auto poses = tools::read_pose_file(a.pose_file, tools::pose_space(a.pose_space));
    if (!poses) return fail("lod", "--pose-file: " + poses.error().message);
    *request.mutable_pose() = encode_skeleton_pose(poses->front());
  }

  LodMesh received;
  try {
    received = client.get_lod(request, std::chrono::seconds(a.deadline_s));
  } catch (const RpcError&) {
    throw;  // main reports RPC failures with their code
  } catch (const std::runtime_error& error) {
    return fail("lod", error.what());
  }
  const v1::LodHeader& h = received.header;
  const auto vertices = static_cast<Eigen::Index>(h.vertex_count());
  const auto faces = static_cast<Eigen::Index>(h.face_count());
  mesh_io::PosedMesh mesh;
  mesh.points = Eigen::Map<const PointMatrix>(received.positions.data(), vertices, 3);
  mesh.faces =
      Eigen::Map<const Eigen::Matrix<uint32_t, Eigen::Dynamic, 3, Eigen::RowMajor>>(received.indices.data(), faces, 3)
          .cast<int32_t>();
  // GetLod's posed form carries positions only: the normals of the posed faces go with them.
  if (faces > 0) mesh.normals = geometry::area_weighted_normals(mesh.points, mesh.faces);
  if (h.texture_coordinates()) {
    mesh = mesh_io::split_seams(
        mesh, Eigen::Map<const mesh_io::UvMatrix>(received.corner_uvs.data(), 3 * faces, 2));
  }
  if (auto written = mesh_io::write_posed_mesh(a.output, mesh); !written.ok()) {
    return fail("lod", written.error().message);
  }
  if (json) {
    print_json(
        {{"output", a.output},
         {"model", a.model},
         {"version", h.model_version()},
         {"level", h.level()},
         {"level_count", h.level_count()},
         {"epsilon", h.epsilon()},
         // Only a level chosen for a view (eq. 7.2) has a tolerated error.
         {"tolerated_error", request.has_pixel_tolerance() ? nlohmann::json(h.tolerated_error()) : nlohmann::json()},
         {"vertices", h.vertex_count()},
         {"faces", h.face_count()},
         {"texture_coordinates", h.texture_coordinates()},
         {"bytes_received", received.bytes_received},
         {"chunks", received.chunk_count}});
  } else {
    std::printf("%s version %llu, level %u of %u (ε = %.4g", a.model.c_str(),
                static_cast<unsigned long long>(h.model_version()), h.level(), h.level_count(),
                static_cast<double>(h.epsilon()));
    if (request.has_pixel_tolerance()) std::printf(", tolerated %.4g", static_cast<double>(h.tolerated_error()));
    std::printf("): %u vertices, %u faces; %llu bytes in %llu chunks\nwrote %s\n", h.vertex_count(), h.face_count(),
                static_cast<unsigned long long>(received.bytes_received),
                static_cast<unsigned long long>(received.chunk_count), a.output.c_str());
  }
  return 0;
}

}  // namespace animspace::cli
