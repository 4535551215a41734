#include "server/pose_batcher.h"

#include <atomic>
#include <memory>
#include <random>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/pmsc_fixtures.h"

namespace animspace::server {
namespace {

// A pose's inputs and outputs, kept at a fixed address while it waits in the batcher.
struct Slot {
  Eigen::VectorXf keys;
  pmsc::PoseEstimate estimate;
  Eigen::VectorXf points;
};

// What the one-pose path gives for `keys`: e_key and f̂.
pmsc::PoseEstimate alone(const pmsc::PmscModel& m, const Eigen::VectorXf& keys) {
  pmsc::PoseEstimate e;
  pmsc::evaluate(m, keys, e);
  return e;
}

// The batched answer equals the one-pose answer: e_key bit for bit (it is computed per pose),
// points within the stated rounding bound of each value's sum.
void expect_one_pose_answer(const pmsc::PmscModel& m, const Slot& slot) {
  const pmsc::PoseEstimate one = alone(m, slot.keys);
  ASSERT_EQ(slot.estimate.key_point_error, one.key_point_error);
  ASSERT_EQ(pmsc::decide(slot.estimate.key_point_error, m.epsilon).status,
            pmsc::decide(one.key_point_error, m.epsilon).status);
  const Eigen::VectorXd tolerance = testing::reconstruction_tolerance(m, one.coordinates);
  for (long i = 0; i < tolerance.size(); ++i) {
    ASSERT_LE(std::abs(slot.points(i) - one.points(i)), tolerance(i)) << "value " << i;
  }
}

TEST(PoseBatcher, ConcurrentCallersGetTheOnePoseAnswersOfTheirOwnPoses) {
  std::mt19937 random(21);
  const pmsc::PmscModel a = testing::random_model(random, 500, 8, 16, false);
  const pmsc::PmscModel b = testing::random_model(random, 300, 5, 10, false);
  ASSERT_GT(a.projection.size(), 0);
  ASSERT_GT(b.projection.size(), 0);
  const auto runtime_a = testing::runtime(a), runtime_b = testing::runtime(b);
  PoseBatcher batcher({std::chrono::microseconds(0), 7});
  constexpr int kThreads = 6, kRounds = 25;
  std::vector<std::thread> threads;
  std::atomic<int> failures{0};
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 mine(100 + static_cast<unsigned>(t));
      for (int round = 0; round < kRounds; ++round) {
        const bool use_b = (round + t) % 3 == 0;
        const pmsc::PmscModel& m = use_b ? b : a;
        const pmsc::Subspace& runtime = use_b ? *runtime_b : *runtime_a;
        // Groups of 1 to 20 poses: some larger than max_batch, so they span batches.
        std::vector<std::unique_ptr<Slot>> slots(1 + mine() % 20);
        std::vector<PoseBatcher::Pose> poses;
        for (auto& slot : slots) {
          slot = std::make_unique<Slot>();
          slot->keys = testing::random_keys(mine, m);
          slot->points.resize(m.mean.size());
          poses.push_back({&slot->keys, &slot->estimate, slot->points.data()});
        }
        PoseBatcher::Group group;
        batcher.enqueue(runtime, poses, group);
        batcher.await(group);
        if (group.pending()) ++failures;
        for (const auto& slot : slots) {
          expect_one_pose_answer(m, *slot);
          if (::testing::Test::HasFatalFailure()) {
            ++failures;
            return;
          }
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
}

// Poses of one model prepared for the batcher: slots and the poses that point into them.
struct Prepared {
  std::vector<std::unique_ptr<Slot>> slots;
  std::vector<PoseBatcher::Pose> poses;
  Prepared(std::mt19937& random, const pmsc::PmscModel& m, int count) {
    for (int i = 0; i < count; ++i) {
      auto slot = std::make_unique<Slot>();
      slot->keys = testing::random_keys(random, m);
      slot->points.resize(m.mean.size());
      poses.push_back({&slot->keys, &slot->estimate, slot->points.data()});
      slots.push_back(std::move(slot));
    }
  }
};

TEST(PoseBatcher, EnoughWaitingPosesAreTakenIntoOneCallersBatch) {
  std::mt19937 random(22);
  const pmsc::PmscModel m = testing::random_model(random, 200, 5, 10, false);
  const auto runtime = testing::runtime(m);
  PoseBatcher batcher({std::chrono::microseconds(0), 64});
  Prepared first(random, m, 2), second(random, m, 2);  // together min_batch (4)
  ASSERT_EQ(batcher.options().min_batch, 4u);
  PoseBatcher::Group g1, g2;
  batcher.enqueue(*runtime, first.poses, g1);
  batcher.enqueue(*runtime, second.poses, g2);
  // One await reconstructs everything waiting for the model: the second group is done without
  // anyone awaiting it.
  batcher.await(g1);
  EXPECT_FALSE(g2.pending());
  for (const Prepared* p : {&first, &second}) {
    for (const auto& slot : p->slots) expect_one_pose_answer(m, *slot);
  }
  batcher.await(g2);  // returns at once
}

TEST(PoseBatcher, BelowTheMinimumBatchEachCallerComputesItsOwn) {
  std::mt19937 random(25);
  const pmsc::PmscModel m = testing::random_model(random, 200, 5, 10, false);
  const auto runtime = testing::runtime(m);
  PoseBatcher batcher({std::chrono::microseconds(0), 64});
  Prepared first(random, m, 1), second(random, m, 2);  // 3 waiting: one product would not pay
  PoseBatcher::Group g1, g2;
  batcher.enqueue(*runtime, first.poses, g1);
  batcher.enqueue(*runtime, second.poses, g2);
  batcher.await(g1);
  EXPECT_TRUE(g2.pending()) << "left for its own caller, on another core";
  batcher.await(g2);
  for (const Prepared* p : {&first, &second}) {
    for (const auto& slot : p->slots) expect_one_pose_answer(m, *slot);
  }
}

TEST(PoseBatcher, WithdrawnPosesAreNeverWritten) {
  std::mt19937 random(23);
  const pmsc::PmscModel m = testing::random_model(random, 200, 5, 10, false);
  const auto runtime = testing::runtime(m);
  PoseBatcher batcher({std::chrono::microseconds(0), 64});
  Slot dropped;
  dropped.keys = testing::random_keys(random, m);
  dropped.points = Eigen::VectorXf::Constant(m.mean.size(), -7.0f);
  const PoseBatcher::Pose pose{&dropped.keys, &dropped.estimate, dropped.points.data()};
  {
    PoseBatcher::Group gone;
    batcher.enqueue(*runtime, {&pose, 1}, gone);
  }  // destroyed unawaited (a stream frame skipped after a cancel): withdrawn
  // A batch of everything waiting: it would take the dropped pose had it stayed.
  Prepared kept(random, m, 4);
  PoseBatcher::Group group;
  batcher.enqueue(*runtime, kept.poses, group);
  batcher.await(group);
  for (const auto& slot : kept.slots) expect_one_pose_answer(m, *slot);
  EXPECT_TRUE((dropped.points.array() == -7.0f).all());
}

TEST(PoseBatcher, ADelayLetsABatchFillFromAnotherThread) {
  std::mt19937 random(24);
  const pmsc::PmscModel m = testing::random_model(random, 200, 5, 10, false);
  const auto runtime = testing::runtime(m);
  // A delay far longer than the test: the batch can only start because it filled.
  PoseBatcher batcher({std::chrono::microseconds(60'000'000), 2});
  Slot first, second;
  for (Slot* slot : {&first, &second}) {
    slot->keys = testing::random_keys(random, m);
    slot->points.resize(m.mean.size());
  }
  const PoseBatcher::Pose p1{&first.keys, &first.estimate, first.points.data()};
  const PoseBatcher::Pose p2{&second.keys, &second.estimate, second.points.data()};
  PoseBatcher::Group g1, g2;
  batcher.enqueue(*runtime, {&p1, 1}, g1);
  std::thread late([&] {
    batcher.enqueue(*runtime, {&p2, 1}, g2);
    batcher.await(g2);
  });
  batcher.await(g1);
  late.join();
  expect_one_pose_answer(m, first);
  expect_one_pose_answer(m, second);
}

}  // namespace
}  // namespace animspace::server
