#include "server/render_thread.h"

#include <utility>

namespace animspace::server {

Result<std::unique_ptr<RenderThread>> RenderThread::start(render::EglPlatform platform, size_t queue_depth) {
  return start([platform] { return render::make_egl_renderer(platform); }, queue_depth);
}

Result<std::unique_ptr<RenderThread>> RenderThread::start(MakeRenderer make_renderer, size_t queue_depth) {
  std::unique_ptr<RenderThread> self(new RenderThread(queue_depth));
  RenderThread* raw = self.get();
  self->thread_ = std::thread([raw, make_renderer = std::move(make_renderer)] { raw->run(make_renderer); });
  std::unique_lock lock(self->mutex_);
  self->wake_.wait(lock, [raw] { return raw->started_; });
  if (!self->start_status_.ok()) {
    Error error = self->start_status_.error();
    lock.unlock();
    self->thread_.join();
    self->stopping_ = true;  // nothing left to join in the destructor
    return error;
  }
  return self;
}

RenderThread::~RenderThread() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool RenderThread::submit(Job job) {
  {
    std::lock_guard lock(mutex_);
    if (stopping_ || queue_.size() >= queue_depth_) return false;
    queue_.push_back(std::move(job));
  }
  wake_.notify_one();
  return true;
}

size_t RenderThread::waiting() const {
  std::lock_guard lock(mutex_);
  return queue_.size();
}

void RenderThread::run(const MakeRenderer& make_renderer) {
  // The context is created here and stays current on this thread for its whole life.
  auto renderer = make_renderer();
  {
    std::lock_guard lock(mutex_);
    started_ = true;
    if (renderer) {
      description_ = (*renderer)->description();
    } else {
      start_status_ = renderer.error();
    }
  }
  wake_.notify_all();
  if (!renderer) return;

  for (;;) {
    Job job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) break;
      job = std::move(queue_.front());
      queue_.pop_front();
    }
    if (job.abandoned && job.abandoned()) {
      job.dropped("abandoned by the caller before drawing");
      continue;
    }
    job.done((*renderer)->render(job.scene));
  }
  // Shutdown: whatever still waits is answered, never silently dropped.
  std::deque<Job> left;
  {
    std::lock_guard lock(mutex_);
    left.swap(queue_);
  }
  for (auto& job : left) job.dropped("the server is shutting down");
}

}  // namespace animspace::server
