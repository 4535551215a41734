// A minimal fork-join loop over an index range, for the few kernels that are worth threads.
//
// Core links nothing but Eigen and OpenMesh (STYLE.md §1), so this is std::thread: the range is
// cut into one contiguous chunk per worker (cache-friendly: each thread writes its own rows),
// and small ranges run inline because starting a thread costs tens of microseconds.
#pragma once

#include <algorithm>
#include <cstdint>
#include <thread>
#include <vector>

namespace animspace {

// Calls body(begin, end) over disjoint chunks covering [0, count). Runs inline when `count` is
// below `min_per_thread` · 2 or the machine has one core. `body` must be safe to call
// concurrently on disjoint ranges.
template <typename Body>
void parallel_for_chunks(int64_t count, int64_t min_per_thread, Body&& body) {
  const int64_t hardware = std::max<int64_t>(1, std::thread::hardware_concurrency());
  const int64_t workers = std::min<int64_t>(hardware, count / std::max<int64_t>(1, min_per_thread));
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
    if (begin < end) threads.emplace_back([&body, begin, end] { body(begin, end); });
  }
  body(int64_t{0}, std::min(count, chunk));
  for (auto& thread : threads) thread.join();
}

}  // namespace animspace
