// The threads that do request work. gRPC's callback threads only receive, admit and send; every
// evaluation, load and retrain runs here, so a slow request never stalls the transport and the
// server decides how many cores serving may use (issue #6 "work runs on a pool the server owns").
//
// The queue itself is unbounded on purpose: admission (server/admission.h) bounds the calls that
// can be waiting, and refusing at admission answers RESOURCE_EXHAUSTED before any work is queued.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace animspace::server {

class WorkPool {
 public:
  // `threads` ≥ 1. `name` labels the threads in logs and debuggers.
  WorkPool(int threads, std::string name);
  ~WorkPool();  // runs what is queued, then joins
  WorkPool(const WorkPool&) = delete;
  WorkPool& operator=(const WorkPool&) = delete;

  // Queues `task`. Returns false (and drops it) once stop() has begun.
  bool submit(std::function<void()> task);
  // Stops accepting work, runs the queue dry and joins the threads. Idempotent.
  void stop();

  int thread_count() const { return static_cast<int>(threads_.size()); }
  size_t queued() const;

 private:
  void run();

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

// Threads for the request pool when the flag says 0: one per core.
int default_work_threads();

}  // namespace animspace::server
