#include "server/pose_batcher.h"

#include <algorithm>
#include <cassert>

namespace animspace::server {

PoseBatcher::Group::~Group() {
  if (batcher_ != nullptr) batcher_->withdraw(*this);
}

bool PoseBatcher::Group::pending() const {
  if (batcher_ == nullptr) return false;
  std::lock_guard lock(batcher_->mutex_);
  return remaining_ > 0;
}

PoseBatcher::PoseBatcher(Options options) : options_(options) { assert(options_.max_batch >= 1); }

PoseBatcher::~PoseBatcher() {
  std::lock_guard lock(mutex_);
  assert(lanes_.empty());  // every group was awaited or withdrawn
}

void PoseBatcher::enqueue(const pmsc::PmscModel& model, std::span<const Pose> poses, Group& group) {
  std::lock_guard lock(mutex_);
  assert(group.remaining_ == 0);
  group.batcher_ = this;
  group.model_ = &model;
  group.remaining_ = poses.size();
  if (poses.empty()) return;
  Lane& lane = lanes_[&model];
  for (const Pose& pose : poses) lane.waiting.push_back({pose, &group});
  // A thread holding a batch open for `delay` may now have enough.
  if (options_.delay.count() > 0) changed_.notify_all();
}

void PoseBatcher::await(Group& group) {
  std::unique_lock lock(mutex_);
  while (group.remaining_ > 0) {
    auto lane = lanes_.find(group.model_);
    assert(lane != lanes_.end());
    if (!lane->second.reconstructing && !lane->second.waiting.empty()) {
      run_batch(lock, *group.model_, lane->second);
    } else {
      changed_.wait(lock);
    }
  }
}

void PoseBatcher::withdraw(Group& group) {
  std::unique_lock lock(mutex_);
  if (group.remaining_ == 0) return;
  auto lane = lanes_.find(group.model_);
  assert(lane != lanes_.end());
  auto& waiting = lane->second.waiting;
  const auto removed = std::remove_if(waiting.begin(), waiting.end(), [&](const Job& job) { return job.group == &group; });
  group.remaining_ -= static_cast<size_t>(waiting.end() - removed);
  waiting.erase(removed, waiting.end());
  const bool taken = group.remaining_ > 0;
  if (!taken && !lane->second.reconstructing && waiting.empty()) lanes_.erase(lane);
  // The rest is in a batch being reconstructed into this group's memory: wait for it (the batch
  // erases the lane when it leaves it empty).
  changed_.wait(lock, [&] { return group.remaining_ == 0; });
}

void PoseBatcher::run_batch(std::unique_lock<std::mutex>& lock, const pmsc::PmscModel& model, Lane& lane) {
  lane.reconstructing = true;
  if (options_.delay.count() > 0 && lane.waiting.size() < options_.max_batch) {
    changed_.wait_for(lock, options_.delay, [&] { return lane.waiting.size() >= options_.max_batch; });
  }
  const size_t size = std::min(lane.waiting.size(), options_.max_batch);
  std::vector<Job> batch(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
  lane.waiting.erase(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
  lock.unlock();

  std::vector<const pmsc::PoseEstimate*> estimates(size);
  std::vector<float*> destinations(size);
  for (size_t i = 0; i < size; ++i) {
    pmsc::estimate_coordinates(model, *batch[i].pose.key_values, *batch[i].pose.estimate);
    estimates[i] = batch[i].pose.estimate;
    destinations[i] = batch[i].pose.points;
  }
  pmsc::reconstruct(model, estimates, destinations);

  lock.lock();
  for (const Job& job : batch) --job.group->remaining_;
  lane.reconstructing = false;
  if (lane.waiting.empty()) lanes_.erase(&model);
  changed_.notify_all();
}

}  // namespace animspace::server
