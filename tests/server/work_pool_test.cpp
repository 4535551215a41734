// The request pool and admission control.
#include "server/work_pool.h"

#include <atomic>
#include <set>
#include <thread>

#include <gtest/gtest.h>

#include "server/admission.h"

namespace animspace::server {
namespace {

TEST(WorkPool, RunsEveryTaskOnItsOwnThreadsAndDrainsOnStop) {
  std::atomic<int> done{0};
  std::mutex mutex;
  std::set<std::thread::id> threads;
  {
    WorkPool pool(3, "test");
    EXPECT_EQ(pool.thread_count(), 3);
    for (int i = 0; i < 500; ++i) {
      ASSERT_TRUE(pool.submit([&] {
        {
          std::lock_guard lock(mutex);
          threads.insert(std::this_thread::get_id());
        }
        done.fetch_add(1);
      }));
    }
    pool.stop();
    EXPECT_EQ(done.load(), 500) << "stop() runs what was queued";
    EXPECT_FALSE(pool.submit([] {})) << "nothing is accepted after stop()";
  }
  EXPECT_EQ(threads.count(std::this_thread::get_id()), 0u);
  EXPECT_LE(threads.size(), 3u);
}

TEST(Admission, AdmitsUpToTheLimitAndFreesSlotsWhenTicketsGo) {
  Admission admission(2);
  auto a = admission.try_admit();
  auto b = admission.try_admit();
  ASSERT_TRUE(a && b);
  EXPECT_FALSE(admission.try_admit());
  EXPECT_EQ(admission.admitted(), 2u);
  a->release();
  a->release();  // idempotent: one slot, freed once
  EXPECT_EQ(admission.admitted(), 1u);
  auto c = admission.try_admit();
  EXPECT_TRUE(c);
  b.reset();  // destruction frees too
  c.reset();
  EXPECT_EQ(admission.admitted(), 0u);
}

TEST(Admission, NeverAdmitsMoreThanTheLimitUnderContention) {
  Admission admission(4);
  std::atomic<uint32_t> peak{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 2000; ++i) {
        auto ticket = admission.try_admit();
        if (!ticket) continue;
        uint32_t now = admission.admitted();
        uint32_t seen = peak.load();
        while (now > seen && !peak.compare_exchange_weak(seen, now)) {
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_LE(peak.load(), 4u);
  EXPECT_EQ(admission.admitted(), 0u);
}

}  // namespace
}  // namespace animspace::server
