// animspace-loadtest against real daemons: short, bounded runs whose reports must add up —
// requests = successes + errors by code, hit + blend + miss = evaluated poses, the per-second
// timeline sums to the totals, and the servers' own counters (read here, independently) moved
// by exactly what the report says — and three replicas balanced round-robin, every one serving.
#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"
#include "core/demo/demo_repository.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "core/misslog/miss_log.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/metrics_scrape.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;

class LoadtestTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repo_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(repo_->path()).ok());
  }
  static void TearDownTestSuite() {
    delete repo_;
    repo_ = nullptr;
  }

  // Each daemon writes its miss logs into its own folder, `daemon_dir(i)` for the i-th started.
  std::unique_ptr<DaemonProcess> start_daemon(const std::vector<std::string>& extra = {}) {
    const auto dir = daemon_dir(daemons_++);
    std::filesystem::create_directories(dir);
    std::vector<std::string> args{"--model-repository", repo_->path().string(), "--miss-log-dir", dir.string(),
                                  "--renderer", "none"};
    args.insert(args.end(), extra.begin(), extra.end());
    auto daemon = std::make_unique<DaemonProcess>(args, dir);
    Client client(daemon->address());
    EXPECT_TRUE(testing::wait_until_serving(client));
    return daemon;
  }

  // Runs the load tester; returns its exit code and leaves its JSON report in `report`.
  int loadtest(const std::string& arguments, nlohmann::json* report) {
    const auto json = work_.path() / "report.json";
    std::filesystem::remove(json);
    const std::string command = harness::program_path("animspace-loadtest").string() + " " + arguments + " --json " + json.string() +
                                " > " + (work_.path() / "out.txt").string() + " 2>&1";
    const int status = std::system(command.c_str());
    std::ifstream in(json);
    if (in) *report = nlohmann::json::parse(in);
    std::ifstream out(work_.path() / "out.txt");
    output_.assign(std::istreambuf_iterator<char>(out), {});
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  std::filesystem::path daemon_dir(int i) const { return work_.path() / ("daemon-" + std::to_string(i)); }

  // The arm's frames with their points pushed along y, as a sequence folder (reference.obj +
  // frames.pc2): far from anything trained, so the cache blends or misses them.
  std::string pushed_arm_sequence() const {
    const auto folder = work_.path() / "pushed-arm";
    if (std::filesystem::exists(folder)) return folder.string();
    std::filesystem::create_directories(folder);
    auto arm = container::read_file(arm_frames());
    EXPECT_TRUE(arm.ok());
    auto frames = arm->float_matrix(container::sections::kSequenceFrames);
    EXPECT_TRUE(frames.ok());
    mesh_io::PointCache cache;
    cache.num_points = static_cast<int>(frames->cols() / 3);
    cache.samples = *frames;
    for (Eigen::Index f = 0; f < cache.samples.rows(); ++f) {
      for (Eigen::Index i = 0; i < cache.samples.cols(); i += 3) cache.samples(f, i + 1) += 0.05f * static_cast<float>(i % 7);
    }
    EXPECT_TRUE(mesh_io::write_pc2(folder / "frames.pc2", cache).ok());
    TriangleMesh reference;
    reference.V = Eigen::Map<const PointMatrix>(frames->row(0).data(), cache.num_points, 3);
    reference.F.resize(1, 3);
    reference.F << 0, 1, 2;
    EXPECT_TRUE(mesh_io::write_triangle_mesh(folder / "reference.obj", reference).ok());
    return folder.string();
  }

  static std::string arm_frames() { return (repo_->path() / "arm" / "1" / "model.anim").string(); }

  // The arithmetic every step of every report must satisfy.
  static void expect_step_adds_up(const nlohmann::json& step, uint64_t batch) {
    const auto requests = step["requests"].get<uint64_t>();
    const auto ok = step["ok"].get<uint64_t>();
    uint64_t by_code = 0;
    for (const auto& [code, count] : step["statusCodeDistribution"].items()) by_code += count.get<uint64_t>();
    EXPECT_EQ(by_code, requests) << "every request ends with one status";
    EXPECT_EQ(ok + step["errors"].get<uint64_t>(), requests);
    const auto poses = step["poses"].get<uint64_t>();
    EXPECT_EQ(step["hits"].get<uint64_t>() + step["blends"].get<uint64_t>() + step["misses"].get<uint64_t>(), poses)
        << "hit + blend + miss = successful evaluations";
    EXPECT_EQ(poses, ok * batch);
    uint64_t timeline_ok = 0, timeline_poses = 0;
    for (const auto& second : step["timeline"]) {
      timeline_ok += second["ok"].get<uint64_t>();
      timeline_poses += second["poses"].get<uint64_t>();
    }
    EXPECT_EQ(timeline_ok, ok);
    EXPECT_EQ(timeline_poses, poses);
    const auto& p = step["latencyDistribution"];
    for (size_t i = 1; i < p.size(); ++i) EXPECT_GE(p[i]["latency_us"].get<double>(), p[i - 1]["latency_us"].get<double>());
  }

  static TempDir* repo_;
  TempDir work_;
  int daemons_ = 0;
  std::string output_;
};

TempDir* LoadtestTest::repo_ = nullptr;

TEST_F(LoadtestTest, ClosedLoopStepsAddUpAndMatchTheServersCounters) {
  auto daemon = start_daemon();
  nlohmann::json report;
  ASSERT_EQ(loadtest("--server " + daemon->address() + " --model arm-pmsc --sequence " + arm_frames() +
                         " --select 1::2 --batch 3 --concurrency 1,3 --duration-s 20 --max-requests 40",
                     &report),
            0)
      << output_;
  ASSERT_EQ(report["steps"].size(), 2u);
  for (const auto& step : report["steps"]) {
    EXPECT_EQ(step["requests"].get<uint64_t>(), 40u) << "bounded by --max-requests, well inside the duration";
    EXPECT_EQ(step["errors"].get<uint64_t>(), 0u);
    expect_step_adds_up(step, 3);
    // The only client of this daemon: its own counters moved by exactly the report's numbers.
    const auto& delta = step["server_delta"];
    EXPECT_EQ(delta["requests"].get<uint64_t>(), step["ok"].get<uint64_t>());
    EXPECT_EQ(delta["poses"].get<uint64_t>(), step["poses"].get<uint64_t>());
    EXPECT_EQ(delta["hits"].get<uint64_t>(), step["hits"].get<uint64_t>());
    EXPECT_EQ(delta["blends"].get<uint64_t>(), step["blends"].get<uint64_t>());
    EXPECT_EQ(delta["misses"].get<uint64_t>(), step["misses"].get<uint64_t>());
  }
  EXPECT_EQ(report["steps"][1]["concurrency"].get<int>(), 3);
}

// Issue #55 item 6: a load test is test traffic. Its blends and misses are served and counted but
// kept out of the miss log — and so out of retraining — unless --log-misses asks for them; the
// metric says how many were kept out and why.
TEST_F(LoadtestTest, ALoadTestLeavesTheMissLogUnchangedUnlessAsked) {
  const int metrics_port = testing::free_tcp_port();
  auto daemon = start_daemon({"--metrics-listen", "127.0.0.1:" + std::to_string(metrics_port)});
  const auto log = daemon_dir(0) / "arm-pmsc.misses";
  const auto records_in_log = [&]() -> size_t {
    if (!std::filesystem::exists(log)) return 0;
    auto records = misslog::read_records(log, 0, nullptr);
    EXPECT_TRUE(records.ok()) << records.error().message;
    return records.ok() ? records->size() : 0;
  };
  const std::string run = "--server " + daemon->address() + " --model arm-pmsc --sequence " + pushed_arm_sequence() +
                          " --batch 4 --concurrency 1 --duration-s 20 --max-requests 15";
  const auto not_hits = [](const nlohmann::json& report) {
    uint64_t n = 0;
    for (const auto& step : report["steps"]) n += step["blends"].get<uint64_t>() + step["misses"].get<uint64_t>();
    return n;
  };

  nlohmann::json report;
  uint64_t skipped = 0;
  for (const char* rpc : {"evaluate", "stream"}) {
    ASSERT_EQ(loadtest(run + " --rpc " + rpc, &report), 0) << output_;
    ASSERT_GT(not_hits(report), 0u) << "the pushed frames must give blends or misses for the test to mean anything";
    EXPECT_EQ(records_in_log(), 0u) << rpc << ": the load test's misses reached the miss log";
    skipped += not_hits(report);
  }
  const auto page = testing::scrape_metrics(metrics_port);
  ASSERT_TRUE(page.has_value());
  EXPECT_EQ(testing::metric_value(*page, "animspace_misses_not_logged_total{model=\"arm-pmsc\",reason=\"skipped\"}")
                .value_or(0),
            static_cast<double>(skipped))
      << *page;

  // Asked for, every blend and miss is logged.
  ASSERT_EQ(loadtest(run + " --log-misses", &report), 0) << output_;
  EXPECT_EQ(records_in_log(), not_hits(report));
}

TEST_F(LoadtestTest, StreamsAndOpenLoopAddUpToo) {
  auto daemon = start_daemon();
  nlohmann::json report;
  ASSERT_EQ(loadtest("--server " + daemon->address() + " --model arm-pmsc --sequence " + arm_frames() +
                         " --rpc stream --window 4 --concurrency 2 --duration-s 20 --max-requests 60",
                     &report),
            0)
      << output_;
  const auto& stream = report["steps"][0];
  EXPECT_EQ(stream["requests"].get<uint64_t>(), 60u);
  expect_step_adds_up(stream, 1);
  EXPECT_EQ(stream["server_delta"]["poses"].get<uint64_t>(), 60u);

  // Open loop, 40 requests/s for 1.5 s: 60 are due (k/40 < 1.5 for k = 0…59), sent or left unsent.
  ASSERT_EQ(loadtest("--server " + daemon->address() + " --model arm-pmsc --sequence " + arm_frames() +
                         " --rate 40 --duration-s 1.5",
                     &report),
            0)
      << output_;
  const auto& open = report["steps"][0];
  EXPECT_EQ(open["mode"], "open");
  EXPECT_EQ(open["requests"].get<uint64_t>() + open["unsent"].get<uint64_t>(), 60u);
  expect_step_adds_up(open, 1);
}

TEST_F(LoadtestTest, BadArgumentsAreRefusedByName) {
  auto daemon = start_daemon();
  nlohmann::json report;
  EXPECT_EQ(loadtest("--server " + daemon->address() + " --model arm-pmsc --sequence " + arm_frames() +
                         " --rpc stream --rate 10",
                     &report),
            2);
  EXPECT_NE(output_.find("--rate: a stream paces itself"), std::string::npos) << output_;
  EXPECT_EQ(loadtest("--server " + daemon->address() + " --model arm-pmsc", &report), 2);
  EXPECT_NE(output_.find("give --sequence"), std::string::npos) << output_;
  EXPECT_EQ(loadtest("--server localhost:1 --server localhost:2 --model arm-pmsc --sequence " + arm_frames(), &report),
            2);
  EXPECT_NE(output_.find("--server localhost:1: several servers"), std::string::npos) << output_;
}

TEST_F(LoadtestTest, ThreeReplicasRoundRobinEveryOneServesWithoutErrors) {
  std::vector<std::unique_ptr<DaemonProcess>> replicas;
  for (int r = 0; r < 3; ++r) replicas.push_back(start_daemon());
  std::string servers;
  for (const auto& r : replicas) servers += " --server " + r->address();
  nlohmann::json report;
  ASSERT_EQ(loadtest(servers + " --model arm-pmsc --sequence " + arm_frames() +
                         " --concurrency 4 --duration-s 20 --max-requests 90",
                     &report),
            0)
      << output_;
  const auto& step = report["steps"][0];
  EXPECT_EQ(step["errors"].get<uint64_t>(), 0u);
  EXPECT_EQ(step["ok"].get<uint64_t>(), 90u);
  expect_step_adds_up(step, 1);
  // Each replica asked on its own: every one served, and together exactly the report's calls.
  uint64_t total = 0;
  for (const auto& r : replicas) {
    Client client(r->address());
    const auto stats = client.stats();
    uint64_t poses = 0;
    for (const auto& m : stats.models()) poses += m.model() == "arm-pmsc" ? m.poses() : 0;
    EXPECT_GT(poses, 0u) << r->address() << " got no calls";
    total += poses;
  }
  EXPECT_EQ(total, 90u);
}

}  // namespace
}  // namespace animspace
