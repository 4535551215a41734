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

void PoseBatcher::enqueue(const pmsc::Subspace& subspace, std::span<const Pose> poses, Group& group) {
  std::lock_guard lock(mutex_);
  assert(group.remaining_ == 0);
  group.batcher_ = this;
  group.subspace_ = &subspace;
  group.remaining_ = poses.size();
  if (poses.empty()) return;
  Lane& lane = lanes_[&subspace];
  for (const Pose& pose : poses) lane.waiting.push_back({pose, &group});
  // A thread holding a batch open for `delay` may now have enough.
  if (options_.delay.count() > 0) changed_.notify_all();
}

void PoseBatcher::await(Group& group) {
  std::unique_lock lock(mutex_);
  while (group.remaining_ > 0) {
    auto lane = lanes_.find(group.subspace_);
    assert(lane != lanes_.end());
    const size_t waiting = lane->second.waiting.size();
    if (lane->second.batching || waiting == 0) {
      changed_.wait(lock);  // a batch is being taken or holds this group's poses
    } else if (waiting >= options_.min_batch || options_.delay.count() > 0) {
      compute(lock, *group.subspace_, lane->second, nullptr);
    } else {
      compute(lock, *group.subspace_, lane->second, &group);
    }
  }
}

void PoseBatcher::withdraw(Group& group) {
  std::unique_lock lock(mutex_);
  if (group.remaining_ == 0) return;
  auto lane = lanes_.find(group.subspace_);
  assert(lane != lanes_.end());
  auto& waiting = lane->second.waiting;
  const auto removed = std::remove_if(waiting.begin(), waiting.end(), [&](const Job& job) { return job.group == &group; });
  group.remaining_ -= static_cast<size_t>(waiting.end() - removed);
  waiting.erase(removed, waiting.end());
  if (lane->second.computing == 0 && waiting.empty()) lanes_.erase(lane);
  // The rest is being reconstructed into this group's memory: wait for it (the thread doing so
  // erases the lane when it leaves it empty).
  changed_.wait(lock, [&] { return group.remaining_ == 0; });
}

void PoseBatcher::compute(std::unique_lock<std::mutex>& lock, const pmsc::Subspace& subspace, Lane& lane,
                          const Group* own) {
  std::vector<Job> batch;
  if (own == nullptr) {
    lane.batching = true;
    if (options_.delay.count() > 0 && lane.waiting.size() < options_.max_batch) {
      changed_.wait_for(lock, options_.delay, [&] { return lane.waiting.size() >= options_.max_batch; });
    }
    const size_t size = std::min(lane.waiting.size(), options_.max_batch);
    batch.assign(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
    lane.waiting.erase(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
  } else {
    // Too few poses wait for one product to pay: this caller computes its own, and the others
    // theirs, on the other cores.
    const auto mine = std::stable_partition(lane.waiting.begin(), lane.waiting.end(),
                                            [&](const Job& job) { return job.group == own; });
    const size_t size = std::min(static_cast<size_t>(mine - lane.waiting.begin()), options_.max_batch);
    if (size == 0) {  // its poses are in a batch that is finishing: nothing to take
      changed_.wait(lock);
      return;
    }
    batch.assign(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
    lane.waiting.erase(lane.waiting.begin(), lane.waiting.begin() + static_cast<long>(size));
  }
  ++lane.computing;
  lock.unlock();

  const size_t size = batch.size();
  std::vector<const pmsc::PoseEstimate*> estimates(size);
  std::vector<float*> destinations(size);
  for (size_t i = 0; i < size; ++i) {
    const Pose& pose = batch[i].pose;
    static const Eigen::VectorXf kNoChecks;
    subspace.estimate(*pose.key_values, pose.check_values != nullptr ? *pose.check_values : kNoChecks, *pose.estimate);
    estimates[i] = batch[i].pose.estimate;
    destinations[i] = batch[i].pose.points;
  }
  subspace.reconstruct(estimates, destinations);

  lock.lock();
  for (const Job& job : batch) --job.group->remaining_;
  --lane.computing;
  if (own == nullptr) lane.batching = false;
  if (lane.computing == 0 && lane.waiting.empty()) lanes_.erase(&subspace);
  changed_.notify_all();
}

}  // namespace animspace::server
