#include "server/services/render_service.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/common/format.h"
#include "core/geometry/bounding_sphere.h"
#include "core/illumination/illumination_io.h"
#include "core/lod/selection.h"
#include "core/pmsc/pmsc_io.h"
#include "core/render/camera.h"
#include "core/render/heat_legend.h"
#include "core/render/png.h"
#include "server/model_lookup.h"
#include "server/pose_evaluation.h"
#include "server/status_mapping.h"
#include "server/unary_call.h"
#include "server/validation.h"

namespace animspace::server {
namespace {

using Request = v1::RenderThumbnailRequest;
using Clock = std::chrono::steady_clock;

constexpr int kDefaultSamples = 4;

// Size, samples, background, shading and camera: everything that does not depend on the model.
grpc::Status read_view(const Request& request, const ServerOptions& options, render::Scene& scene) {
  const uint32_t max_px = options.max_thumbnail_px;
  for (const auto& [field, value] : {std::pair{"width_px", request.width_px()}, {"height_px", request.height_px()}}) {
    if (value < 1 || value > max_px) {
      return invalid_argument(std::string(field) + ": expected 1.." + std::to_string(max_px) +
                              " pixels (--max-thumbnail-px), got " + std::to_string(value));
    }
  }
  scene.width = static_cast<int>(request.width_px());
  scene.height = static_cast<int>(request.height_px());

  scene.samples = request.samples() == 0 ? kDefaultSamples : static_cast<int>(request.samples());
  if (scene.samples != 1 && scene.samples != 2 && scene.samples != 4 && scene.samples != 8) {
    return invalid_argument("samples: expected 1, 2, 4 or 8 (0 = 4), got " + std::to_string(request.samples()));
  }

  if (request.background_rgba_size() != 0) {
    if (request.background_rgba_size() != 4) {
      return invalid_argument("background_rgba: expected 4 values (RGBA), got " +
                              std::to_string(request.background_rgba_size()));
    }
    for (int c = 0; c < 4; ++c) {
      const float v = request.background_rgba(c);
      if (!(v >= 0 && v <= 1)) {
        return invalid_argument("background_rgba[" + std::to_string(c) + "]: expected a value in [0, 1], got " +
                                std::to_string(v));
      }
      scene.background[c] = v;
    }
  }

  switch (request.shading()) {
    case Request::SHADING_UNSPECIFIED:
    case Request::SHADING_BLINN_PHONG:
      scene.shading = render::Shading::kBlinnPhong;
      break;
    case Request::SHADING_LAMBERT:
      scene.shading = render::Shading::kLambert;
      break;
    default:
      return invalid_argument("shading: unknown value " + std::to_string(static_cast<int>(request.shading())));
  }

  for (const auto& [field, value] : {std::pair{"tolerance_px", request.tolerance_px()},
                                     std::pair{"pixel_tolerance", request.pixel_tolerance()}}) {
    if (!std::isfinite(value) || value < 0) {
      return invalid_argument(std::string(field) + ": expected a finite value ≥ 0 (0 = full detail), got " +
                              std::to_string(value));
    }
  }
  if (request.tolerance_px() != 0 && request.pixel_tolerance() != 0 &&
      request.tolerance_px() != request.pixel_tolerance()) {
    return invalid_argument("tolerance_px: " + format_number(request.tolerance_px()) +
                            " disagrees with pixel_tolerance (its deprecated name), " +
                            format_number(request.pixel_tolerance()) + "; send tolerance_px only");
  }

  if (request.has_camera()) {
    const v1::Camera& c = request.camera();
    render::Camera camera;
    for (const auto& [field, values, out] :
         {std::tuple{"camera.eye", &c.eye(), &camera.eye}, {"camera.target", &c.target(), &camera.target},
          {"camera.up", &c.up(), &camera.up}}) {
      if (values->size() != 3) {
        return invalid_argument(std::string(field) + ": expected 3 values, got " + std::to_string(values->size()));
      }
      *out = Eigen::Vector3d((*values)[0], (*values)[1], (*values)[2]);
    }
    camera.vertical_fov_rad = c.vertical_fov_rad();
    if (Status valid = render::validate_camera(camera, "camera"); !valid.ok()) return to_grpc_status(valid.error());
    scene.camera = camera;
  }
  return grpc::Status::OK;
}

// The rows of a float32 PointArray the server itself encoded, as N × 3 points.
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

// tolerance_px, or the deprecated pixel_tolerance an older client sends (read_view checked
// that they agree when both are set).
float thumbnail_tolerance_px(const Request& request) {
  return request.tolerance_px() != 0 ? request.tolerance_px() : request.pixel_tolerance();
}

// Poses the animation-space model (or a PMSC model's engine) at `globals`, at the level the
// thumbnail's pixel tolerance allows (eq. 7.2 with the thumbnail's own camera and width).
grpc::Status pose_skinned(const LoadedModel& model, const animation_space::TransformList& globals,
                          const Request& request, bool level_zero_only, render::Scene& scene, uint32_t& level_out) {
  const animation_space::AnimationSpaceModel* skinned = model.animation_space.get();
  animation_space::evaluate(*skinned, globals, scene.points);
  const auto& lods = model.lod_levels;
  const float tolerance_px = thumbnail_tolerance_px(request);
  if (tolerance_px > 0 && lods && lods->count() > 1 && !level_zero_only) {
    const double aspect = static_cast<double>(scene.width) / scene.height;
    if (!scene.camera) {
      auto framed = render::frame_bounding_box(scene.points, aspect);
      if (!framed) return to_grpc_status(framed.error());
      scene.camera = *framed;
    }
    // Eq. 7.2 needs the depth of the nearest point of a sphere around the posed mesh.
    const geometry::BoundingSphere sphere = geometry::bounding_sphere(scene.points);
    lod::PixelTolerance view;
    view.tolerance_px = tolerance_px;
    view.viewport_width_px = scene.width;
    view.horizontal_fov_rad = render::horizontal_fov(*scene.camera, aspect);
    view.distance = (scene.camera->eye - sphere.centre).norm();
    auto choice = lod::level_for_view(*lods, view, sphere.radius);
    if (!choice) return to_grpc_status(choice.error());
    if (choice->level > 0) {
      skinned = &lods->levels[static_cast<size_t>(choice->level)].model;
      animation_space::evaluate(*skinned, globals, scene.points);
    }
    level_out = static_cast<uint32_t>(choice->level);
  }
  scene.faces = skinned->faces;
  if (skinned->has_tangents()) animation_space::evaluate_normals(*skinned, globals, scene.normals);
  return grpc::Status::OK;
}

// The per-point error a PMSC model's ε was calibrated to flag (training option error_tolerance,
// model units), or 0 when the model stores none.
double error_tolerance(const LoadedModel& model) {
  auto options = pmsc::load_training_options(model.container, model.name);
  return options.ok() && std::isfinite(options->error_tolerance) && options->error_tolerance > 0
             ? options->error_tolerance
             : 0.0;
}

// Thesis Fig. 8.6 style: per point, how far what the cache returned (`estimate`) is from the
// truth, drawn as the scene's heat map.
grpc::Status draw_heat(const LoadedModel& model, const Request& request, const Eigen::Ref<const PointMatrix>& truth,
                       const Eigen::Ref<const PointMatrix>& estimate, render::Scene& scene,
                       v1::RenderThumbnailResponse* response) {
  scene.heat = (truth - estimate).rowwise().norm();
  // Red means the error asked for, else the per-point error the model's ε was calibrated to flag
  // (its error tolerance): a hit's errors then read as a fraction of what the model promises.
  // ε_max itself bounds the RMS key-point error, a far smaller number than a point's error, and
  // turned a hit mostly red.
  const double largest = scene.heat.size() == 0 ? 0.0 : static_cast<double>(scene.heat.maxCoeff());
  if (!std::isfinite(largest)) {
    return invalid_argument("full_values: |full − estimate| overflows float32; expected values on the model's scale");
  }
  double scale = request.heat_max();
  if (scale == 0) scale = error_tolerance(model);
  if (scale == 0) scale = largest;
  scene.heat_max = static_cast<float>(scale);
  response->set_heat_max_error(largest);
  response->set_heat_scale_max(scale);
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
    if (view.heat_from_full_gather()) served.engine->indirect(input.lights, served.gather, all, full);
    return draw_heat(model, request, Eigen::Map<const PointMatrix>(full.data(), radiance.rows(), 3), radiance, scene,
                     response);
  }
  PointMatrix colours = radiance;
  if (total) {
    Eigen::VectorXf direct;
    served.engine->direct(input.lights, all, direct);
    colours += Eigen::Map<const PointMatrix>(direct.data(), colours.rows(), 3);
  }
  // A reconstruction may dip a little below zero where the radiance is near zero; light is not
  // negative, so the picture shows 0 there.
  colours = colours.cwiseMax(0.0f);
  double white = view.white_radiance();
  if (white == 0) {
    std::vector<double> largest(static_cast<size_t>(colours.rows()));
    for (long i = 0; i < colours.rows(); ++i) largest[static_cast<size_t>(i)] = colours.row(i).maxCoeff();
    auto at = largest.begin() + static_cast<long>(0.99 * static_cast<double>(largest.size() - 1));
    std::nth_element(largest.begin(), at, largest.end());
    white = largest.empty() || *at <= 0 ? 1.0 : *at;
  }
  scene.vertex_colours = std::move(colours);
  scene.exposure = static_cast<float>(1.0 / white);
  scene.srgb = true;
  scene.shading = render::Shading::kUnlit;
  return grpc::Status::OK;
}

// Fills the scene's geometry and overlays from the request's source (SPEC: a posed mesh from
// PMSC key points, a skeleton pose, a stored sequence frame, or the rest pose).
grpc::Status pose_scene(ServiceEnvironment& env, const LoadedModel& model, const Request& request,
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
      // Key points index the full-detail mesh: with the overlay on, draw full detail.
      if (grpc::Status s = pose_skinned(model, globals, request, request.show_key_points(), scene, level); !s.ok()) {
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
        if (grpc::Status s = pose_skinned(model, rest, request, false, scene, level); !s.ok()) return s;
        break;
      }
      auto rest = model.container.points(container::sections::kRestPoints);
      if (!rest) return unsupported_by_kind(model, "it stores no rest pose to draw");
      scene.points = std::move(*rest);
      if (grpc::Status s = stored_faces(model, scene); !s.ok()) return s;
      break;
    }
  }
  scene.wireframe = request.show_wireframe();
  if (request.show_key_points()) scene.key_points.assign(model.pmsc->key_points.begin(), model.pmsc->key_points.end());
  response->set_lod_level(level);
  return grpc::Status::OK;
}

// Runs on the request pool after the render thread has drawn: the heat legend (when asked for,
// with the scale the scene used), PNG, then the answer.
void encode_and_finish(render::Image image, Clock::time_point drawn_from, int64_t max_message_bytes,
                       std::optional<double> legend_max, v1::RenderThumbnailResponse* response,
                       const CallFinisher& finish) {
  if (legend_max) response->set_heat_legend_drawn(render::draw_heat_legend(image, *legend_max));
  auto png = render::encode_png(image);
  if (!png) {
    finish(to_grpc_status(png.error()));
    return;
  }
  // The response also carries a few small fields; the PNG is what can be large.
  constexpr int64_t kAllowance = 1024;
  if (static_cast<int64_t>(png->size()) + kAllowance > max_message_bytes) {
    finish({grpc::StatusCode::RESOURCE_EXHAUSTED,
            "png: the thumbnail encodes to " + std::to_string(png->size()) + " bytes, over --max-message-bytes " +
                std::to_string(max_message_bytes) + "; ask for a smaller width_px/height_px"});
    return;
  }
  response->set_png(std::move(*png));
  response->set_render_ms(std::chrono::duration<double, std::milli>(Clock::now() - drawn_from).count());
  finish(grpc::Status::OK);
}

}  // namespace

grpc::ServerUnaryReactor* RenderServiceImpl::RenderThumbnail(grpc::CallbackServerContext* context,
                                                             const grpc::ByteBuffer* request_bytes,
                                                             grpc::ByteBuffer* response_bytes) {
  return serve_unary_deferred<Request, v1::RenderThumbnailResponse>(
      env_, {context, request_bytes, response_bytes}, "RenderService/RenderThumbnail", Access::kUser, env_.request_pool,
      [this](const CallControl& call, const Request* request, v1::RenderThumbnailResponse* response,
             const CallFinisher& finish) {
        if (env_.renderer == nullptr) {
          finish({grpc::StatusCode::UNAVAILABLE, "this server draws no thumbnails: " + env_.renderer_unavailable});
          return;
        }
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) {
          finish(std::move(s));
          return;
        }
        render::Scene scene;
        if (grpc::Status s = read_view(*request, env_.options, scene); !s.ok()) {
          finish(std::move(s));
          return;
        }
        if (grpc::Status s = pose_scene(env_, *model, *request, scene, response); !s.ok()) {
          finish(std::move(s));
          return;
        }
        response->set_width_px(request->width_px());
        response->set_height_px(request->height_px());
        response->set_model_version(model->version);

        const auto started = Clock::now();
        grpc::CallbackServerContext* ctx = call.context();
        WorkPool& pool = env_.request_pool;
        const int64_t max_bytes = env_.options.max_message_bytes;
        const std::optional<double> legend_max =
            request->show_heat_legend() ? std::optional<double>(response->heat_scale_max()) : std::nullopt;
        RenderThread::Job job;
        job.scene = std::move(scene);
        job.abandoned = [ctx] { return !CallControl(ctx, nullptr).stop_status().ok(); };
        job.done = [started, max_bytes, legend_max, response, finish, &pool](Result<render::Image> image) {
          if (!image) {
            finish(to_grpc_status(image.error()));
            return;
          }
          auto encode = [image = std::move(*image), started, max_bytes, legend_max, response, finish]() mutable {
            encode_and_finish(std::move(image), started, max_bytes, legend_max, response, finish);
          };
          // PNG encoding leaves the render thread free for the next draw.
          if (!pool.submit(encode)) encode();
        };
        job.dropped = [ctx, finish](const char* why) {
          grpc::Status stop = CallControl(ctx, nullptr).stop_status();
          finish(stop.ok() ? grpc::Status(grpc::StatusCode::UNAVAILABLE, why) : stop);
        };
        if (!env_.renderer->submit(std::move(job))) {
          finish({grpc::StatusCode::RESOURCE_EXHAUSTED,
                  "render queue full: " + std::to_string(env_.renderer->queue_depth()) +
                      " thumbnails are already waiting (--render-queue-depth); retry with backoff"});
        }
      });
}

}  // namespace animspace::server
