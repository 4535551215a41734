#include "server/services/render_service.h"

#include <chrono>
#include <optional>
#include <string>
#include <utility>

#include "core/thumbnail/thumbnail_png.h"
#include "server/model_lookup.h"
#include "server/status_mapping.h"
#include "server/thumbnail_scene.h"
#include "server/thumbnail_view.h"
#include "server/unary_call.h"

namespace animspace::server {
namespace {

using Request = v1::RenderThumbnailRequest;
using Clock = std::chrono::steady_clock;

// Runs on the request pool after the render thread has drawn: the heat legend (when asked for,
// with the scale the scene used), PNG, then the answer.
void encode_and_finish(render::Image image, Clock::time_point drawn_from, int64_t max_message_bytes,
                       std::optional<double> legend_max, v1::RenderThumbnailResponse* response,
                       const CallFinisher& finish) {
  auto encoded = thumbnail::encode_thumbnail(std::move(image), legend_max);
  if (!encoded) {
    finish(to_grpc_status(encoded.error()));
    return;
  }
  if (legend_max) response->set_heat_legend_drawn(encoded->heat_legend_drawn);
  // The response also carries a few small fields; the PNG is what can be large.
  constexpr int64_t kAllowance = 1024;
  if (static_cast<int64_t>(encoded->png.size()) + kAllowance > max_message_bytes) {
    finish(resource_exhausted("png: the thumbnail encodes to " + std::to_string(encoded->png.size()) +
                              " bytes, over --max-message-bytes " + std::to_string(max_message_bytes) +
                              "; ask for a smaller width_px/height_px"));
    return;
  }
  response->set_png(std::move(encoded->png));
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
          finish(unavailable("this server draws no thumbnails: " + env_.renderer_unavailable));
          return;
        }
        std::shared_ptr<const LoadedModel> model;
        if (grpc::Status s = find_model(env_.registry, request->model(), "model", model, &call); !s.ok()) {
          finish(std::move(s));
          return;
        }
        render::Scene scene;
        if (grpc::Status s = read_thumbnail_view(*request, env_.options, scene); !s.ok()) {
          finish(std::move(s));
          return;
        }
        if (grpc::Status s = build_thumbnail_scene(env_, *model, *request, scene, response); !s.ok()) {
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
          finish(stop.ok() ? unavailable(why) : stop);
        };
        if (!env_.renderer->submit(std::move(job))) {
          finish(resource_exhausted("render queue full: " + std::to_string(env_.renderer->queue_depth()) +
                                    " thumbnails are already waiting (--render-queue-depth); retry with backoff"));
        }
      });
}

}  // namespace animspace::server
