// Dynamic batching (issue #25; the role of Triton's dynamic batcher): the poses waiting for the
// same served model version — a unary batch, concurrent unary calls, a stream's read-ahead — are
// reconstructed as one matrix product, so the basis (crane: 7.3 MB) is read once per batch rather
// than once per pose (core/pmsc/subspace.h, `reconstruct`).
//
// A caller enqueues its poses (cheap, any thread) and later awaits them on a pool thread. There
// is no batching thread: whoever awaits while nobody is taking a batch for that model takes what
// is waiting — up to `max_batch` poses, oldest first — and reconstructs it for everyone, so
// waiting never depends on another pool thread being free. Fewer than `min_batch` poses gain
// nothing from one product (below 4 columns OpenBLAS's product is one matrix–vector product per
// pose, core/common/kernels.h), so then each caller computes only its own, and callers on
// different cores run in parallel instead of one of them sleeping. By default that is all the batching
// there is: only poses already waiting join a batch, and no pose waits for a batch to fill.
// `delay` lets an operator trade latency for throughput (Triton's max_queue_delay_microseconds):
// the thread that takes a batch first waits up to `delay` for it to reach `max_batch`.
//
// Only f̂ is batched. Each pose's eq. 2 (its coordinates, e_key, e_check and so its verdict) is computed
// alone, by the thread that takes the batch, so a verdict never depends on the batch; its points
// differ from the one-pose path's by float rounding only (pmsc::reconstruction_rounding_bound).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <map>
#include <mutex>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/common/kernels.h"
#include "core/pmsc/subspace.h"

namespace animspace::server {

class PoseBatcher {
 public:
  struct Options {
    std::chrono::microseconds delay{0};
    size_t max_batch = 64;  // ≥ 1
    size_t min_batch = static_cast<size_t>(kBlasGemmMinColumns);
  };

  // One pose to estimate: its key values (K·D), where its estimate goes, where f̂ goes (N·D
  // floats) and its check values (C·D; null or empty: none — they travel with the pose because
  // its error estimate, and so its verdict, is computed with its coordinates). All must stay
  // valid until the group is awaited or withdrawn.
  struct Pose {
    const Eigen::VectorXf* key_values = nullptr;
    pmsc::PoseEstimate* estimate = nullptr;
    float* points = nullptr;
    const Eigen::VectorXf* check_values = nullptr;
  };

  // The poses one caller enqueued together. Await or withdraw it before its poses' memory goes:
  // the destructor withdraws what is still queued.
  class Group {
   public:
    Group() = default;
    ~Group();
    Group(const Group&) = delete;
    Group& operator=(const Group&) = delete;
    bool pending() const;

   private:
    friend class PoseBatcher;
    PoseBatcher* batcher_ = nullptr;
    const pmsc::Subspace* subspace_ = nullptr;
    size_t remaining_ = 0;  // poses not yet reconstructed (batcher's mutex)
  };

  explicit PoseBatcher(Options options);
  ~PoseBatcher();
  PoseBatcher(const PoseBatcher&) = delete;
  PoseBatcher& operator=(const PoseBatcher&) = delete;

  // Queues `poses` of `subspace` (a model version's runtime, which must outlive the group) into `group` (not in use).
  void enqueue(const pmsc::Subspace& subspace, std::span<const Pose> poses, Group& group);
  // Returns once every pose of `group` is estimated and reconstructed, taking and reconstructing
  // batches of the group's model itself whenever nobody else is.
  void await(Group& group);
  // Removes the group's poses that no batch has taken yet, and waits for those already taken.
  void withdraw(Group& group);

  const Options& options() const { return options_; }

 private:
  struct Job {
    Pose pose;
    Group* group;
  };
  struct Lane {
    std::vector<Job> waiting;  // oldest first
    bool batching = false;     // a thread is taking or computing a batch of everyone's poses
    int computing = 0;         // threads computing poses taken from this lane
  };

  // Takes a batch from `lane` — everyone's poses, or only `own`'s when not null — and
  // reconstructs it; the lock is released while it computes.
  void compute(std::unique_lock<std::mutex>& lock, const pmsc::Subspace& subspace, Lane& lane, const Group* own);

  const Options options_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::map<const pmsc::Subspace*, Lane> lanes_;  // model versions with poses waiting or in a batch
};

}  // namespace animspace::server
