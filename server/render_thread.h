// The one thread that owns the EGL context (an OpenGL context is current on one thread only).
//
// Requests queue to it with a bound (--render-queue-depth): a thumbnail that finds the queue full
// is refused at once with RESOURCE_EXHAUSTED rather than waiting behind work the server cannot
// finish in time. The thread only draws; posing before and PNG encoding after run on the request
// pool, so that on a small machine the cores overlap them with the next draw.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/common/result.h"
#include "core/render/renderer.h"

namespace animspace::server {

// Creates the renderer; called once, on the render thread, which then owns it.
using MakeRenderer = std::function<Result<std::unique_ptr<render::Renderer>>()>;

class RenderThread {
 public:
  struct Job {
    render::Scene scene;
    // Asked just before drawing: a caller that went away (deadline, cancel) is not drawn for.
    std::function<bool()> abandoned;
    // Called on the render thread with the image or the renderer's error.
    std::function<void(Result<render::Image>)> done;
    // Called instead of `done` when the job is not drawn: abandoned, or the server stopping.
    std::function<void(const char* why)> dropped;
  };

  // Starts the thread and creates the renderer on it; returns once it is ready.
  // Errors: the renderer's (kFailedPrecondition naming the EGL platform and error).
  static Result<std::unique_ptr<RenderThread>> start(render::EglPlatform platform, size_t queue_depth);
  // The same with any renderer (tests inject one that records what it is asked to draw).
  static Result<std::unique_ptr<RenderThread>> start(MakeRenderer make_renderer, size_t queue_depth);

  // Drops queued jobs (their `done` gets an error), finishes the one drawing, joins.
  ~RenderThread();
  RenderThread(const RenderThread&) = delete;
  RenderThread& operator=(const RenderThread&) = delete;

  // Queues a job. False when `queue_depth` jobs are already waiting (or stopping): the job is
  // not taken and its `done` is never called.
  bool submit(Job job);

  const std::string& description() const { return description_; }
  size_t queue_depth() const { return queue_depth_; }
  size_t waiting() const;

 private:
  explicit RenderThread(size_t queue_depth) : queue_depth_(queue_depth) {}
  void run(const MakeRenderer& make_renderer);

  const size_t queue_depth_;
  std::string description_;
  std::thread thread_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> queue_;
  bool stopping_ = false;
  // Start-up hand-over: the renderer is created on the thread, its outcome reported here.
  bool started_ = false;
  Status start_status_;
};

}  // namespace animspace::server
