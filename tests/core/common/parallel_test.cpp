#include "core/common/parallel.h"

#include <atomic>
#include <mutex>
#include <vector>

#include <gtest/gtest.h>

namespace animspace {
namespace {

class ParallelGrainsTest : public ::testing::Test {
 protected:
  void TearDown() override { set_thread_limit(0); }
};

// Every index is visited exactly once, in ranges of at most a grain, whatever the count, grain
// and thread limit.
TEST_F(ParallelGrainsTest, VisitsEveryIndexOnceInRangesOfAtMostAGrain) {
  for (int threads : {1, 2, 4}) {
    set_thread_limit(threads);
    for (int64_t count : {0, 1, 7, 1000, 1001}) {
      for (int64_t grain : {1, 7, 64, 5000}) {
        std::vector<std::atomic<int>> visits(static_cast<size_t>(count));
        std::atomic<bool> oversized{false};
        parallel_for_grains(count, 1, grain, [&](int64_t begin, int64_t end) {
          const bool inline_run = threads == 1 || count < 2;
          if (!inline_run && end - begin > grain) oversized = true;
          for (int64_t i = begin; i < end; ++i) ++visits[static_cast<size_t>(i)];
        });
        for (int64_t i = 0; i < count; ++i) {
          ASSERT_EQ(visits[static_cast<size_t>(i)].load(), 1)
              << "index " << i << " of " << count << ", grain " << grain << ", " << threads << " threads";
        }
        EXPECT_FALSE(oversized) << count << " items, grain " << grain;
      }
    }
  }
}

// A loop inside a body runs inline on that body's thread (parallel.h), as parallel_for_chunks's.
TEST_F(ParallelGrainsTest, ALoopInsideABodyRunsInline) {
  set_thread_limit(2);
  std::mutex mutex;
  std::vector<int64_t> inner_calls;
  parallel_for_grains(4, 1, 1, [&](int64_t, int64_t) {
    int64_t calls = 0;
    parallel_for_grains(100, 1, 3, [&](int64_t begin, int64_t end) {
      EXPECT_EQ(begin, 0);
      EXPECT_EQ(end, 100);
      ++calls;
    });
    const std::lock_guard<std::mutex> lock(mutex);
    inner_calls.push_back(calls);
  });
  EXPECT_EQ(inner_calls, std::vector<int64_t>(4, 1));
}

}  // namespace
}  // namespace animspace
