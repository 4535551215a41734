// The training examples a miss log gives a retrain (core/misslog/miss_frames.h): which records
// become frames, which are skipped and why, checked on a hand-made log.
#include "core/misslog/miss_frames.h"

#include <gtest/gtest.h>

#include "core/misslog/miss_log.h"
#include "tests/support/test_support.h"
#include "tests/support/pmsc_fixtures.h"

namespace animspace::misslog {
namespace {

// Two 3-D points, one key point (point 1): full values (a, b, c, x, y, z) are consistent with
// key values (x, y, z).
pmsc::PmscModel two_point_model() {
  pmsc::PmscModel m;
  m.channel_count = 3;
  m.point_count = 2;
  m.control_point_count = 2;
  m.key_points = {1};
  m.epsilon = {0.1, 0.2};
  return m;
}

MissRecord record(uint64_t version, std::vector<float> keys, std::vector<float> full) {
  MissRecord r;
  r.model_version = version;
  r.unix_time_us = 1;
  r.status = pmsc::CacheStatus::kMiss;
  r.blend_weight = 1;
  r.channel_count = 3;
  r.key_values = std::move(keys);
  r.full_values = std::move(full);
  return r;
}

TEST(MissFrames, KeepsConsistentCompletedMissesAndCountsWhatItLeavesOut) {
  testing::TempDir dir;
  const auto path = dir.path() / "m.misses";
  {
    auto log = MissLog::open(path, FsyncPolicy::kNever, std::chrono::milliseconds(10));
    ASSERT_TRUE(log.ok()) << log.error().message;
    // 1: completed, consistent. 2: never completed. 3: a "full pose" of zeros (the poisoning of
    // issue #21). 4: logged by version 2, whose key set this model does not know: taken as is.
    for (MissRecord r : {record(1, {4, 5, 6}, {1, 2, 3, 4, 5, 6}), record(1, {4, 5, 6}, {}),
                         record(1, {4, 5, 6}, {0, 0, 0, 0, 0, 0}), record(2, {9, 9, 9}, {7, 8, 9, 1, 1, 1})}) {
      ASSERT_TRUE((*log)->append(r).ok());
    }
  }
  auto frames = read_miss_frames(path, 0, two_point_model(), 1);
  ASSERT_TRUE(frames.ok()) << frames.error().message;
  ASSERT_EQ(frames->frames.rows(), 2);
  ASSERT_EQ(frames->frames.cols(), 6);
  EXPECT_EQ(frames->frames.row(0), (Eigen::RowVectorXf(6) << 1, 2, 3, 4, 5, 6).finished());
  EXPECT_EQ(frames->frames.row(1), (Eigen::RowVectorXf(6) << 7, 8, 9, 1, 1, 1).finished());
  EXPECT_EQ(frames->skipped, 1u);
  EXPECT_EQ(frames->inconsistent, 1u);
  EXPECT_EQ(frames->last_sequence, 4u);

  // After the watermark only record 4 is read.
  frames = read_miss_frames(path, 3, two_point_model(), 1);
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(frames->frames.rows(), 1);
  EXPECT_EQ(frames->skipped + frames->inconsistent, 0u);

  // No log yet: no misses.
  frames = read_miss_frames(dir.path() / "absent.misses", 0, two_point_model(), 1);
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(frames->frames.rows(), 0);
  EXPECT_EQ(frames->last_sequence, 0u);
}

// Three points of one channel, a one-vector subspace a = (1, 2, 2)/3, keys at points 0 and 1:
// key values (1, 1) give f̂ = (0.6, 1.2, 1.2) (pmsc_model_test's hand-worked example).
pmsc::PmscModel three_point_model() { return testing::three_point_model({0, 1}, {0.1, 0.5}); }

MissRecord partial_record(uint64_t version, std::vector<uint32_t> points, std::vector<float> full) {
  MissRecord r = record(version, {1, 1}, std::move(full));
  r.channel_count = 1;
  r.full_points = std::move(points);
  return r;
}

TEST(MissFrames, CompletesPartialFramesWithKeyValuesAndTheEstimate) {
  pmsc::PmscModel model = three_point_model();
  ASSERT_TRUE(pmsc::prepare_projection(model).ok());
  testing::TempDir dir;
  const auto path = dir.path() / "m.misses";
  {
    auto log = MissLog::open(path, FsyncPolicy::kNever, std::chrono::milliseconds(10));
    ASSERT_TRUE(log.ok()) << log.error().message;
    // 1: point 2 computed. 2: key point 0 computed (consistent). 3: key point 1 computed as 0,
    // not its key value 1. 4: another model version (its key set is unknown). 5: a point the
    // model does not have.
    for (MissRecord r : {partial_record(1, {2}, {5}), partial_record(1, {0}, {1}), partial_record(1, {1}, {0}),
                         partial_record(2, {2}, {5}), partial_record(1, {7}, {5})}) {
      ASSERT_TRUE((*log)->append(r).ok());
    }
  }
  auto frames = read_miss_frames(path, 0, model, 1);
  ASSERT_TRUE(frames.ok()) << frames.error().message;
  ASSERT_EQ(frames->frames.rows(), 2);
  EXPECT_EQ(frames->partial, 2u);
  EXPECT_EQ(frames->inconsistent, 1u);
  EXPECT_EQ(frames->skipped, 2u);
  // Key points take their key values, computed points their values, the rest f̂ — here from an
  // independent evaluation of the record's key values.
  pmsc::PoseEstimate estimate;
  evaluate(model, Eigen::Vector2f(1, 1), estimate);
  EXPECT_NEAR(estimate.points(2), 1.2, 1e-6);  // 1.8 · 2/3 by hand
  EXPECT_EQ(frames->frames.row(0), (Eigen::RowVectorXf(3) << 1, 1, 5).finished());
  EXPECT_EQ(frames->frames.row(1), (Eigen::RowVectorXf(3) << 1, 1, estimate.points(2)).finished());
}

// A log created before partial frames holds the whole frame retraining would complete anyway;
// a newer log and a whole-frame record are left as they are.
TEST(MissFrames, FitToFormatCompletesPartialFramesOnlyForLogsBeforeThem) {
  pmsc::PmscModel model = three_point_model();
  ASSERT_TRUE(pmsc::prepare_projection(model).ok());
  MissRecord old_log = partial_record(1, {2}, {5});
  fit_to_format(model, kFirstPartialFormatVersion - 1, old_log);
  EXPECT_TRUE(old_log.full_points.empty());
  // Keys (1, 1) at points 0 and 1, point 2 computed as 5 (hand-worked: nothing of f̂ is left).
  EXPECT_EQ(old_log.full_values, (std::vector<float>{1, 1, 5}));
  MissRecord partial_from_keys = partial_record(1, {0}, {1});
  fit_to_format(model, kFirstPartialFormatVersion - 1, partial_from_keys);
  // Point 2 takes the estimate f̂_2 = 1.8 · 2/3 = 1.2 (by hand).
  ASSERT_EQ(partial_from_keys.full_values.size(), 3u);
  EXPECT_EQ(partial_from_keys.full_values[0], 1.0f);
  EXPECT_NEAR(partial_from_keys.full_values[2], 1.2, 1e-6);

  MissRecord current = partial_record(1, {2}, {5});
  fit_to_format(model, kFirstPartialFormatVersion, current);
  EXPECT_EQ(current.full_points, (std::vector<uint32_t>{2}));
  EXPECT_EQ(current.full_values, (std::vector<float>{5}));
  MissRecord whole = record(1, {1, 1}, {1, 1, 1});
  whole.channel_count = 1;
  fit_to_format(model, 1, whole);
  EXPECT_EQ(whole.full_values, (std::vector<float>{1, 1, 1}));
}

}  // namespace
}  // namespace animspace::misslog
