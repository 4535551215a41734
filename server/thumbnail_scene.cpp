#include "server/thumbnail_scene.h"

#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/atlas/atlas_io.h"
#include "core/illumination/illumination_io.h"
#include "core/pmsc/pmsc_io.h"
#include "core/thumbnail/heat_map.h"
#include "core/thumbnail/radiance_colours.h"
#include "core/thumbnail/skinned_scene.h"
#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/status_mapping.h"
#include "server/thumbnail_view.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

using Request = v1::RenderThumbnailRequest;

PointMatrix points_of(const v1::PointArray& array) {
  PointMatrix points(static_cast<Eigen::Index>(array.point_count()), 3);
  std::memcpy(points.data(), array.data().data(), array.data().size());
  return points;
}

grpc::Status stored_faces(const LoadedModel& model, render::Scene& scene) {
  if (!model.container.has_section(container::sections::kFaces)) {
    return unsupported_by_kind(model, "it stores no faces (section " + std::string(container::sections::kFaces) +
                                          "), so there is no surface to draw");
  }
  auto faces = model.container.faces(container::sections::kFaces);
  if (!faces) return to_grpc_status(faces.error());
  scene.faces = std::move(*faces);
  return grpc::Status::OK;
}

// Poses the animation-space model (or a PMSC model's engine) at `globals`, at the level the
// thumbnail's screen tolerance allows, or at full detail with `level_zero_only`.
grpc::Status pose_skinned(const LoadedModel& model, const animation_space::TransformList& globals,
                          const Request& request, bool level_zero_only, render::Scene& scene, uint32_t& level_out) {
  const double tolerance_px = level_zero_only ? 0.0 : thumbnail_tolerance_px(request);
  auto level = thumbnail::pose_skinned(*model.animation_space, model.lod_levels.get(), globals, tolerance_px, scene);
  if (!level) return to_grpc_status(level.error());
  level_out = static_cast<uint32_t>(*level);
  return grpc::Status::OK;
}

// The per-point error a PMSC model's ε was calibrated to flag, in model units (training option
// error_tolerance; for a relative-tolerance model that fraction of the pose's scale S, the RMS
// point norm of `estimate`), or 0 when the model stores none.
double error_tolerance(const LoadedModel& model, const Eigen::Ref<const PointMatrix>& estimate) {
  auto options = pmsc::load_training_options(model.container, model.name);
  if (!options.ok() || !std::isfinite(options->error_tolerance) || !(options->error_tolerance > 0)) return 0.0;
  if (!options->relative_tolerance) return options->error_tolerance;
  const double scale = estimate.rows() > 0 ? std::sqrt(estimate.cast<double>().rowwise().squaredNorm().mean()) : 0.0;
  return options->error_tolerance * scale;
}

// The heat map of how far what the cache returned (`estimate`) is from `truth` (core/thumbnail/
// heat_map.h), red at heat_max, else at the model's error tolerance, else at the largest error.
grpc::Status draw_heat(const LoadedModel& model, const Request& request, const Eigen::Ref<const PointMatrix>& truth,
                       const Eigen::Ref<const PointMatrix>& estimate, render::Scene& scene,
                       v1::RenderThumbnailResponse* response) {
  const double requested_max = request.heat_max();
  auto heat = thumbnail::heat_map(truth, estimate, requested_max, requested_max == 0 ? error_tolerance(model, estimate) : 0.0,
                                  "full_values", scene);
  if (!heat) return to_grpc_status(heat.error());
  response->set_heat_max_error(heat->largest_error);
  response->set_heat_scale_max(heat->scale_max);
  return grpc::Status::OK;
}

// The key_points source, decoded: the pose and, for a heat map, the full values, both checked
// before the pose is evaluated so that a refused request leaves no trace in the statistics or the
// miss log.
grpc::Status decode_key_points(const LoadedModel& model, const Request& request, PoseInput& input,
                               Eigen::VectorXf& full) {
  if (grpc::Status s = decode_pose(model, request.key_points(), "key_points", input); !s.ok()) return s;
  if (!request.has_full_values()) return grpc::Status::OK;
  return decode_full_values(model, request.full_values(), "full_values", input.key_values, input.check_values, full);
}

// Evaluates the decoded pose through the soft cache into response.pose (counted and logged as any
// pose) and returns its points for the picture: the client asked for a picture and has the points
// API for points, so the response keeps the verdict without them.
grpc::Status evaluate_for_picture(ServiceEnvironment& env, const LoadedModel& model, const PoseInput& input,
                                  v1::RenderThumbnailResponse* response, PointMatrix& points) {
  v1::PoseResult* result = response->mutable_pose();
  if (grpc::Status s = evaluate_pose(env, model, input, PoseOptions{}, result); !s.ok()) return s;
  points = points_of(result->points());
  result->clear_points();
  return grpc::Status::OK;
}

// An illumination model's thumbnail (IlluminationView, Meyer & Anderson 2007 Figs. 5 and 10): its
// surface, coloured by the served radiance for the pose's lights, or by the heat map of the
// served indirect illumination's error; with no source, by the surface's albedo.
grpc::Status illumination_scene(ServiceEnvironment& env, const LoadedModel& model, const Request& request,
                                render::Scene& scene, v1::RenderThumbnailResponse* response) {
  const illumination::ServedIllumination& served = *model.illumination;
  const illumination::SurfaceMesh& surface = served.engine->surface();
  const v1::IlluminationView& view = request.illumination();
  if (!v1::IlluminationView::Radiance_IsValid(view.radiance())) {
    return invalid_argument("illumination.radiance: unknown value " + std::to_string(static_cast<int>(view.radiance())));
  }
  if (!std::isfinite(view.white_radiance()) || view.white_radiance() < 0) {
    return invalid_argument("illumination.white_radiance: expected a finite value ≥ 0 (0 = the 99th percentile of "
                            "the drawn radiance), got " + std::to_string(view.white_radiance()));
  }
  if (view.heat_from_full_gather() && request.has_full_values()) {
    return invalid_argument("illumination.heat_from_full_gather: set together with full_values; the heat map's "
                            "truth is one or the other");
  }
  scene.points = surface.vertices;
  scene.faces = surface.faces;
  scene.normals = surface.normals;
  if (!scene.camera && served.view) {
    scene.camera = render::Camera{served.view->eye, served.view->target, served.view->up, served.view->vertical_fov_rad};
  }
  switch (request.source_case()) {
    case Request::kKeyPoints: break;
    case Request::SOURCE_NOT_SET:
      if (view.heat_from_full_gather()) {
        return invalid_argument("illumination.heat_from_full_gather: needs key_points with a light_set as the source");
      }
      scene.vertex_colours = surface.albedo;  // the room as it is, under the thumbnail's headlight
      return grpc::Status::OK;
    default:
      return unsupported_by_kind(model, "sequence_frame / skeleton_pose: an illumination model draws its surface, "
                                        "lit through key_points (with a light_set) or plain");
  }
  PoseInput input;
  Eigen::VectorXf full;
  if (grpc::Status s = decode_key_points(model, request, input, full); !s.ok()) return s;
  const bool total = view.radiance() != v1::IlluminationView::RADIANCE_INDIRECT;
  const bool heat = request.has_full_values() || view.heat_from_full_gather();
  if (input.lights.empty() && (view.heat_from_full_gather() || (total && !heat))) {
    return invalid_argument(std::string("key_points.light_set: needed for ") +
                            (view.heat_from_full_gather() ? "illumination.heat_from_full_gather"
                                                          : "illumination.radiance RADIANCE_TOTAL (the server computes "
                                                            "the direct part)") +
                            "; send the lights, or ask for RADIANCE_INDIRECT");
  }
  const std::vector<int> all = served.engine->all_points();
  PointMatrix radiance;
  if (grpc::Status s = evaluate_for_picture(env, model, input, response, radiance); !s.ok()) return s;
  if (heat) {
    if (view.heat_from_full_gather()) served.full(input.lights, full);
    return draw_heat(model, request, Eigen::Map<const PointMatrix>(full.data(), radiance.rows(), 3), radiance, scene,
                     response);
  }
  if (total) {
    // The served radiance is the indirect part; the total adds the direct part, which the engine
    // computes for the lights.
    Eigen::VectorXf direct;
    served.engine->direct(input.lights, all, direct);
    radiance += Eigen::Map<const PointMatrix>(direct.data(), radiance.rows(), 3);
  }
  thumbnail::radiance_colours(std::move(radiance), view.white_radiance(), scene);
  return grpc::Status::OK;
}

// The squares along one unit of texture coordinate when checker_squares is 0.
constexpr int kDefaultCheckerSquares = 16;

// The texture_checker fields, checked, and the model's atlas loaded: all before any pose is
// evaluated. `atlas` stays empty without texture_checker.
grpc::Status read_texture_checker(const LoadedModel& model, const Request& request, std::optional<atlas::Atlas>& atlas) {
  if (!request.texture_checker()) {
    if (request.checker_squares() != 0) {
      return invalid_argument("checker_squares: needs texture_checker (the squares are the checker's), got " +
                              std::to_string(request.checker_squares()) + " without it");
    }
    if (request.show_chart_borders()) {
      return invalid_argument("show_chart_borders: needs texture_checker (the borders are the atlas's)");
    }
    return grpc::Status::OK;
  }
  if (request.checker_squares() < 0) {
    return invalid_argument("checker_squares: expected > 0 squares per unit of texture coordinate (0: the default " +
                            std::to_string(kDefaultCheckerSquares) + "), got " +
                            std::to_string(request.checker_squares()));
  }
  if (request.has_full_values()) {
    return invalid_argument("texture_checker: set together with full_values; the surface takes its colour from the "
                            "checker or from the heat map, not both");
  }
  if (model.illumination) {
    return unsupported_by_kind(model, "texture_checker: an illumination model's surface is drawn with its radiance "
                                      "and has no texture atlas");
  }
  auto stored = atlas::load_atlas(model.container, model.info.face_count, model.path.string());
  if (!stored) return to_grpc_status(stored.error());
  if (!*stored) {
    return failed_precondition("texture_checker: model '" + model.name + "' version " + std::to_string(model.version) +
                               " stores no texture atlas (expected atlas sections; `animspace atlas MODEL.anim -o "
                               "OUT.anim` adds one, then serve OUT.anim)");
  }
  atlas = std::move(**stored);
  return grpc::Status::OK;
}

// The checker over the atlas (render::Checker), on the full-detail faces the atlas belongs to.
grpc::Status draw_texture_checker(const LoadedModel& model, const Request& request, const atlas::Atlas& atlas,
                                  render::Scene& scene) {
  if (atlas.uvs.rows() != 3 * scene.faces.rows()) {
    return unsupported_by_kind(model, "texture_checker: its atlas covers " + std::to_string(atlas.uvs.rows() / 3) +
                                          " faces, the drawn mesh has " + std::to_string(scene.faces.rows()));
  }
  scene.corner_uvs = atlas.uvs.cast<float>();
  scene.checker.squares_per_uv =
      static_cast<float>(request.checker_squares() != 0 ? request.checker_squares() : kDefaultCheckerSquares);
  scene.checker.chart_borders = request.show_chart_borders();
  return grpc::Status::OK;
}

}  // namespace

// SPEC: a posed mesh from PMSC key points, a skeleton pose, a stored sequence frame, or the rest
// pose.
grpc::Status build_thumbnail_scene(ServiceEnvironment& env, const LoadedModel& model, const Request& request,
                                   render::Scene& scene, v1::RenderThumbnailResponse* response) {
  uint32_t level = 0;
  if (request.show_key_points() && !model.pmsc) {
    return unsupported_by_kind(model, "show_key_points: it has no key points (only PMSC models do)");
  }
  const bool heat_truth = request.has_full_values() || (model.illumination && request.illumination().heat_from_full_gather());
  if (!heat_truth && (request.heat_max() != 0 || request.show_heat_legend())) {
    return invalid_argument(std::string(request.heat_max() != 0 ? "heat_max" : "show_heat_legend") +
                            ": the heat map needs full_values (and key_points as the source)");
  }
  if (!std::isfinite(request.heat_max()) || request.heat_max() < 0) {
    return invalid_argument("heat_max: expected a finite value ≥ 0 (0 = the model's error tolerance), got " +
                            std::to_string(request.heat_max()));
  }
  std::optional<atlas::Atlas> atlas;
  if (grpc::Status s = read_texture_checker(model, request, atlas); !s.ok()) return s;
  // Key points and the atlas index the full-detail mesh: with either, draw full detail.
  const bool level_zero_only = request.show_key_points() || atlas.has_value();
  if (model.illumination) {
    if (grpc::Status s = illumination_scene(env, model, request, scene, response); !s.ok()) return s;
    scene.wireframe = request.show_wireframe();
    if (request.show_key_points()) scene.key_points.assign(model.pmsc->key_points.begin(), model.pmsc->key_points.end());
    return grpc::Status::OK;
  }
  if (request.has_full_values() && request.source_case() != Request::kKeyPoints) {
    return invalid_argument(
        "full_values: the heat map compares what the soft cache returns for key_points with the full values; "
        "set key_points as the source");
  }
  switch (request.source_case()) {
    case Request::kKeyPoints: {
      if (grpc::Status s = require_pmsc(model, "key_points: it has no soft cache to pose from key points");
          !s.ok()) {
        return s;
      }
      if (model.info.channel_count != 3) {
        return unsupported_by_kind(model, "key_points: its points have " + std::to_string(model.info.channel_count) +
                                              " channels, not 3-D positions to draw");
      }
      PoseInput input;
      Eigen::VectorXf full;
      if (grpc::Status s = decode_key_points(model, request, input, full); !s.ok()) return s;
      if (grpc::Status s = evaluate_for_picture(env, model, input, response, scene.points); !s.ok()) return s;
      if (grpc::Status s = stored_faces(model, scene); !s.ok()) return s;
      if (request.has_full_values()) {
        const auto n = static_cast<uint32_t>(model.info.point_count);
        if (grpc::Status s = draw_heat(model, request, Eigen::Map<const PointMatrix>(full.data(), n, 3), scene.points,
                                       scene, response);
            !s.ok()) {
          return s;
        }
      }
      break;
    }
    case Request::kSkeletonPose: {
      if (grpc::Status s = require_skeleton(model, "skeleton_pose: there is nothing to pose"); !s.ok()) return s;
      animation_space::TransformList globals;
      if (grpc::Status s = decode_skeleton_pose(request.skeleton_pose(), "skeleton_pose",
                                                model.animation_space->skeleton, globals);
          !s.ok()) {
        return s;
      }
      if (grpc::Status s = pose_skinned(model, globals, request, level_zero_only, scene, level); !s.ok()) {
        return s;
      }
      break;
    }
    case Request::kSequenceFrame: {
      if (!model.container.has_section(container::sections::kSequenceFrames) || model.info.channel_count != 3) {
        return unsupported_by_kind(model, "sequence_frame: it stores no sequence of 3-D frames");
      }
      auto row = model.container.float_matrix_row(container::sections::kSequenceFrames, request.sequence_frame());
      if (!row) {
        return invalid_argument("sequence_frame: expected 0.." + std::to_string(model.info.frame_count - 1) +
                                " (the model stores " + std::to_string(model.info.frame_count) + " frames), got " +
                                std::to_string(request.sequence_frame()));
      }
      scene.points = Eigen::Map<const PointMatrix>(row->data(), model.info.point_count, 3);
      if (grpc::Status s = stored_faces(model, scene); !s.ok()) return s;
      break;
    }
    case Request::SOURCE_NOT_SET: {
      if (model.animation_space && model.info.kind == container::ModelKind::kAnimationSpace) {
        const auto rest = animation_space::rest_pose(model.animation_space->skeleton);
        if (grpc::Status s = pose_skinned(model, rest, request, atlas.has_value(), scene, level); !s.ok()) return s;
        break;
      }
      auto rest = model.container.points(container::sections::kRestPoints);
      if (!rest) return unsupported_by_kind(model, "it stores no rest pose to draw");
      scene.points = std::move(*rest);
      if (grpc::Status s = stored_faces(model, scene); !s.ok()) return s;
      break;
    }
  }
  if (atlas) {
    if (grpc::Status s = draw_texture_checker(model, request, *atlas, scene); !s.ok()) return s;
  }
  scene.wireframe = request.show_wireframe();
  if (request.show_key_points()) scene.key_points.assign(model.pmsc->key_points.begin(), model.pmsc->key_points.end());
  if (request.show_heat_legend()) {
    // The legend takes the image's right edge: a camera the renderer would choose frames the
    // model left of it instead (an illumination model keeps its room's stored camera, above).
    if (Status framed = thumbnail::frame_beside_heat_legend(scene, static_cast<int>(request.width_px()),
                                                            static_cast<int>(request.height_px()),
                                                            response->heat_scale_max());
        !framed.ok()) {
      return to_grpc_status(framed.error());
    }
  }
  response->set_lod_level(level);
  return grpc::Status::OK;
}

}  // namespace animspace::server
