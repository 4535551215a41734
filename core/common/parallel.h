// A minimal fork-join loop over an index range, for the few kernels that are worth threads.
//
// Core links nothing but Eigen and OpenMesh (STYLE.md §1), so this is std::thread: the range is
// cut into one contiguous chunk per worker (cache-friendly: each thread writes its own rows),
// and small ranges run inline because starting a thread costs tens of microseconds.
//
// A loop started from inside another loop's body runs inline (issue #38 item 3): the outer loop
// already has every core busy, and a nested split would only add threads to share them. So a
// training that runs its calibration folds in parallel computes each fold exactly as a
// one-thread training does, and the products inside a fold are not split again.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace animspace {

namespace parallel_detail {
inline std::atomic<int> thread_limit{0};         // 0: the machine's cores
inline thread_local bool inside_parallel_body = false;

struct BodyScope {
  bool previous = inside_parallel_body;
  BodyScope() { inside_parallel_body = true; }
  ~BodyScope() { inside_parallel_body = previous; }
};
}  // namespace parallel_detail

// The most threads a parallel_for_chunks uses: the machine's cores unless limited. Process-wide,
// like the machine it describes: a tool's flag, a benchmark's one-thread baseline, or a test that
// compares one thread with two set it before the loops run. 0 restores the default.
inline void set_thread_limit(int threads) { parallel_detail::thread_limit.store(std::max(0, threads)); }

inline int64_t thread_count() {
  const int64_t hardware = std::max<int64_t>(1, std::thread::hardware_concurrency());
  const int limit = parallel_detail::thread_limit.load(std::memory_order_relaxed);
  return limit > 0 ? limit : hardware;
}

// Calls body(begin, end) over disjoint chunks covering [0, count). Runs inline when `count` is
// below `min_per_thread` · 2, the machine has one core (or the limit is 1), or the call comes
// from inside another parallel_for_chunks body. `body` must be safe to call concurrently on
// disjoint ranges.
template <typename Body>
void parallel_for_chunks(int64_t count, int64_t min_per_thread, Body&& body) {
  const int64_t workers = parallel_detail::inside_parallel_body
                              ? 1
                              : std::min<int64_t>(thread_count(), count / std::max<int64_t>(1, min_per_thread));
  if (workers <= 1) {
    if (count > 0) body(int64_t{0}, count);
    return;
  }
  std::vector<std::thread> threads;
  threads.reserve(static_cast<size_t>(workers - 1));
  const int64_t chunk = (count + workers - 1) / workers;
  for (int64_t w = 1; w < workers; ++w) {
    const int64_t begin = w * chunk;
    const int64_t end = std::min(count, begin + chunk);
    if (begin < end) {
      threads.emplace_back([&body, begin, end] {
        const parallel_detail::BodyScope scope;
        body(begin, end);
      });
    }
  }
  {
    const parallel_detail::BodyScope scope;
    body(int64_t{0}, std::min(count, chunk));
  }
  for (auto& thread : threads) thread.join();
}

// As parallel_for_chunks, for loops whose items cost unequally (a gather's points: where their
// rays go decides their cost): the range is cut into grains of `grain` items that the workers
// take in turn, so that no core idles while another still has half the range (contiguous halves
// of the papers' 100k points finished minutes apart). body(begin, end) is called once per grain,
// on whichever worker takes it; the workers and the inline cases are parallel_for_chunks's.
template <typename Body>
void parallel_for_grains(int64_t count, int64_t min_per_thread, int64_t grain, Body&& body) {
  const int64_t workers = parallel_detail::inside_parallel_body
                              ? 1
                              : std::min<int64_t>(thread_count(), count / std::max<int64_t>(1, min_per_thread));
  grain = std::max<int64_t>(1, grain);
  if (workers <= 1) {
    if (count > 0) body(int64_t{0}, count);
    return;
  }
  std::atomic<int64_t> next{0};
  const auto work = [&] {
    const parallel_detail::BodyScope scope;
    for (int64_t begin = next.fetch_add(grain); begin < count; begin = next.fetch_add(grain)) {
      body(begin, std::min(count, begin + grain));
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(static_cast<size_t>(workers - 1));
  for (int64_t w = 1; w < workers; ++w) threads.emplace_back(work);
  work();
  for (auto& thread : threads) thread.join();
}

}  // namespace animspace
