// Files written by an earlier release keep loading (tests/fixtures/release-0.1/README.md): model
// containers of every kind through the daemon's whole load sequence, and a version-1 miss log,
// read and appended to. The expected values are those the fixtures were written with
// (fuzz/make_seed_corpus.cpp at that release), not what today's readers return.
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "core/container/model_container.h"
#include "core/misslog/miss_log.h"
#include "core/model/servable.h"
#include "harness/build_tree.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace fs = std::filesystem;

// tests/CMakeLists.txt defines it as an absolute path (see fuzz_regression_test.cpp for why).
fs::path fixtures() { return harness::source_dir() / "tests" / "fixtures" / "release-0.1"; }

struct ContainerCase {
  const char* file;
  container::ModelKind kind;
  model::FailThrough fail_through;
  bool pmsc;
  bool skeleton;
};

class ReleaseContainerTest : public ::testing::TestWithParam<ContainerCase> {};

TEST_P(ReleaseContainerTest, LoadsAsTheServableItWasWrittenAs) {
  const ContainerCase& c = GetParam();
  auto file = container::read_file(fixtures() / c.file);
  ASSERT_TRUE(file.ok()) << file.error().message;
  auto servable = model::load_servable(*file, c.file);
  ASSERT_TRUE(servable.ok()) << servable.error().message;
  EXPECT_EQ(servable->info.kind, c.kind);
  EXPECT_EQ(servable->info.fail_through, c.fail_through);
  EXPECT_EQ(servable->pmsc != nullptr, c.pmsc);
  EXPECT_EQ(servable->animation_space != nullptr, c.skeleton);
  EXPECT_EQ(servable->lod_levels != nullptr, c.skeleton);
  EXPECT_GT(servable->info.point_count, 0);
}

INSTANTIATE_TEST_SUITE_P(
    Release01, ReleaseContainerTest,
    ::testing::Values(
        ContainerCase{"mesh_sequence.anim", container::ModelKind::kMeshSequence, model::FailThrough::kNone, false, false},
        ContainerCase{"animation_space.anim", container::ModelKind::kAnimationSpace, model::FailThrough::kNone, false,
                      true},
        ContainerCase{"pmsc.anim", container::ModelKind::kPmsc, model::FailThrough::kClient, true, false},
        ContainerCase{"pmsc_engine.anim", container::ModelKind::kPmsc, model::FailThrough::kServer, true, true}));

TEST(ReleaseMissLogTest, Version1LogReadsAndAcceptsAppendsInVersion1) {
  testing::TempDir dir;
  const fs::path path = dir / "two_records.misses";
  fs::copy_file(fixtures() / "two_records.misses", path);

  auto records = misslog::read_records(path, 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  ASSERT_EQ(records->size(), 2U);
  const misslog::MissRecord& blend = (*records)[0];
  EXPECT_EQ(blend.sequence, 1U);
  EXPECT_EQ(blend.status, pmsc::CacheStatus::kBlend);
  EXPECT_EQ(blend.key_point_error, 0.5);
  EXPECT_EQ(blend.blend_weight, 0.25);
  EXPECT_EQ(blend.key_values, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  EXPECT_TRUE(blend.full_values.empty());
  const misslog::MissRecord& miss = (*records)[1];
  EXPECT_EQ(miss.status, pmsc::CacheStatus::kMiss);
  EXPECT_EQ(miss.full_values, (std::vector<float>{1, 2, 3, 4, 5, 6, 7, 8, 9}));

  {
    auto log = misslog::MissLog::open(path, misslog::FsyncPolicy::kNever, std::chrono::milliseconds(0));
    ASSERT_TRUE(log.ok()) << log.error().message;
    EXPECT_EQ((*log)->format_version(), 1U);
    misslog::MissRecord more = miss;
    ASSERT_EQ(*(*log)->append(more), 3U);
  }
  auto again = misslog::read_records(path, 0, nullptr);
  ASSERT_TRUE(again.ok()) << again.error().message;
  ASSERT_EQ(again->size(), 3U);
  EXPECT_EQ((*again)[2].status, pmsc::CacheStatus::kMiss);
  EXPECT_EQ((*again)[2].full_values, miss.full_values);
}

}  // namespace
}  // namespace animspace
