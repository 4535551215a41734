// The `animspace` command line against the real daemon: every server operation answers with
// --json that scripts can parse, the numbers agree with what the client library (or the core,
// in-process) computes for the same request, every command explains itself in --help, and
// progress bars never reach a pipe.
#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/mesh_io/pc2.h"
#include "core/container/sections.h"
#include "harness/daemon_process.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace as = animation_space;
using harness::DaemonProcess;
using testing::TempDir;

struct CliRun {
  int exit_code = -1;
  std::string out;
  std::string err;
};

class CliClientTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repo_ = new TempDir();
    work_ = new TempDir();
    ASSERT_TRUE(demo::write_demo_repository(repo_->path()).ok());
    daemon_ = new DaemonProcess({"--model-repository", repo_->path().string(), "--miss-log-dir",
                                 work_->path().string(), "--renderer", "none"},
                                work_->path());
    client_ = new Client(daemon_->address());
    ASSERT_TRUE(testing::wait_until_serving(*client_));
  }
  static void TearDownTestSuite() {
    delete client_;
    delete daemon_;
    delete work_;
    delete repo_;
  }

  // `animspace -s <daemon> <arguments>`, stdout and stderr kept apart (stderr is a file, not a
  // terminal, as in a script).
  static CliRun cli(const std::string& arguments) {
    const auto err_path = work_->path() / "stderr.txt";
    const std::string command = std::string(ANIMSPACE_CLI_PATH) + " -s " + daemon_->address() + " " + arguments +
                                " 2>" + err_path.string();
    CliRun run;
    FILE* pipe = popen(command.c_str(), "r");
    if (pipe == nullptr) return run;
    char buffer[4096];
    size_t n = 0;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) run.out.append(buffer, n);
    const int status = pclose(pipe);
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::ifstream err(err_path);
    run.err.assign(std::istreambuf_iterator<char>(err), {});
    return run;
  }

  static nlohmann::json json_of(const CliRun& run) {
    EXPECT_EQ(run.exit_code, 0) << run.err;
    try {
      return nlohmann::json::parse(run.out);
    } catch (const nlohmann::json::exception& e) {
      ADD_FAILURE() << "not JSON: " << e.what() << "\n" << run.out;
      return {};
    }
  }

  static std::string arm_frames() { return (repo_->path() / "arm" / "1" / "model.anim").string(); }

  static TempDir* repo_;
  static TempDir* work_;
  static DaemonProcess* daemon_;
  static Client* client_;
};

TempDir* CliClientTest::repo_ = nullptr;
TempDir* CliClientTest::work_ = nullptr;
DaemonProcess* CliClientTest::daemon_ = nullptr;
Client* CliClientTest::client_ = nullptr;

TEST_F(CliClientTest, EveryCommandExplainsItselfInHelp) {
  const std::vector<std::string> commands = {
      "list", "health", "server-info", "describe", "stats", "keys", "evaluate", "play", "pose", "retrain",
      "load", "unload", "lod", "thumbnail", "inspect", "demo-repository", "train-pmsc", "fit", "import-rig",
      "build-lod", "export-lod"};
  const CliRun top = cli("--help");
  ASSERT_EQ(top.exit_code, 0);
  for (const std::string& command : commands) {
    EXPECT_NE(top.out.find("  " + command), std::string::npos) << command << " is missing from --help";
    const CliRun help = cli(command + " --help");
    EXPECT_EQ(help.exit_code, 0) << command;
    EXPECT_NE(help.out.find("Usage:"), std::string::npos) << command;
    // A description line beyond the usage: more than the bare option list.
    EXPECT_GT(help.out.size(), 120u) << command << ":\n" << help.out;
  }
}

TEST_F(CliClientTest, JsonAnswersMatchTheClientLibrary) {
  const nlohmann::json keys = json_of(cli("--json keys arm-pmsc"));
  const KeyPoints expected = client_->describe_key_points("arm-pmsc");
  EXPECT_EQ(keys["key_point_indices"].get<std::vector<uint32_t>>(), expected.indices);
  EXPECT_EQ(keys["control_point_count"].get<uint32_t>(), expected.control_point_count);
  EXPECT_EQ(keys["fail_through"], "FAIL_THROUGH_CLIENT");

  const nlohmann::json list = json_of(cli("--json list"));
  EXPECT_EQ(list["models"].size(), client_->list_models().size());
  EXPECT_EQ(json_of(cli("--json health"))["status"], "SERVING");
  const nlohmann::json info = json_of(cli("--json server-info"));
  EXPECT_FALSE(info["implemented_rpcs"].empty());
  EXPECT_TRUE(json_of(cli("--json stats")).contains("models"));
}

TEST_F(CliClientTest, EvaluateReportsEveryFramesVerdictAndTheErrorAgainstTheFrame) {
  const auto pc2 = work_->path() / "returned.pc2";
  const CliRun run = cli("--json evaluate arm-pmsc " + arm_frames() + " --select 1:41:2 --batch 7 -o " + pc2.string());
  const nlohmann::json report = json_of(run);
  EXPECT_TRUE(run.err.empty()) << "no progress bar on a pipe: " << run.err;
  ASSERT_EQ(report["frames"].get<int>(), 20);
  EXPECT_EQ(report["hits"].get<int>() + report["blends"].get<int>() + report["misses"].get<int>(), 20);
  ASSERT_EQ(report["results"].size(), 20u);

  // Each frame again through the client library, and the returned points against the frame.
  auto stored = container::read_file(arm_frames());
  ASSERT_TRUE(stored.ok());
  auto frames = stored->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());
  const KeyPoints keys = client_->describe_key_points("arm-pmsc");
  auto returned = mesh_io::read_pc2(pc2);
  ASSERT_TRUE(returned.ok()) << returned.error().message;
  ASSERT_EQ(returned->num_frames(), 20);
  double worst = 0;
  for (int i = 0; i < 20; ++i) {
    const int f = 1 + 2 * i;
    const nlohmann::json& row = report["results"][static_cast<size_t>(i)];
    EXPECT_EQ(row["frame"].get<int>(), f);
    const std::span<const float> frame(frames->row(f).data(), static_cast<size_t>(frames->cols()));
    const std::vector<float> values = keys.gather(frame);
    const PoseResult result = client_->evaluate_key_points("arm-pmsc", {values, 3});
    EXPECT_EQ(row["status"], cache_status_name(result.status)) << "frame " << f;
    double max_distance = 0;
    for (Eigen::Index p = 0; p < frames->cols() / 3; ++p) {
      const Eigen::Vector3f got = returned->samples.row(i).segment<3>(3 * p).transpose();
      EXPECT_EQ(got.x(), result.points.point(static_cast<uint32_t>(p))[0]);
      max_distance = std::max(max_distance, double((got - frames->row(f).segment<3>(3 * p).transpose()).norm()));
    }
    EXPECT_NEAR(row["max_point_error"].get<double>(), max_distance, 1e-6 + 1e-5 * max_distance) << "frame " << f;
    worst = std::max(worst, max_distance);
  }
  EXPECT_NEAR(report["max_point_error"].get<double>(), worst, 1e-6 + 1e-5 * worst);
}

TEST_F(CliClientTest, PlayStreamsTheSelectedFramesAndCountsThem) {
  const nlohmann::json report = json_of(cli("--json play arm-pmsc " + arm_frames() + " --select 0:60"));
  EXPECT_EQ(report["frames"].get<int>(), 60);
  EXPECT_EQ(report["hits"].get<int>() + report["blends"].get<int>() + report["misses"].get<int>(), 60);
  EXPECT_GE(report["hit_rate"].get<double>(), 0.0);
  EXPECT_LE(report["hit_rate"].get<double>(), 1.0);
}

TEST_F(CliClientTest, PoseWritesTheSkinnedSequenceAsAPointCache) {
  auto file = container::read_file(repo_->path() / "arm-animspace" / "1" / "model.anim");
  ASSERT_TRUE(file.ok());
  auto model = as::load(*file, "arm-animspace");
  ASSERT_TRUE(model.ok());
  auto rows = file->double_matrix(container::sections::kSequenceBoneTransforms, 16 * model->bone_count());
  ASSERT_TRUE(rows.ok());
  // Two poses in one file: the stored training frames 4 and 9, as global transforms.
  std::ostringstream text;
  text << "# two poses of arm-animspace\n";
  std::vector<as::TransformList> poses;
  for (int f : {4, 9}) {
    poses.push_back(as::pose_from_row(*rows, f, model->bone_count()));
    for (auto& G : poses.back()) {
      G = G.cast<float>().cast<double>();
      for (int r = 0; r < 3; ++r) text << G(r, 0) << ' ' << G(r, 1) << ' ' << G(r, 2) << ' ' << G(r, 3) << '\n';
    }
  }
  const auto pose_file = work_->path() / "poses.txt";
  std::ofstream(pose_file) << text.str();
  const auto pc2 = work_->path() / "posed.pc2";
  const nlohmann::json report =
      json_of(cli("--json pose arm-animspace --pose-file " + pose_file.string() + " -o " + pc2.string()));
  EXPECT_EQ(report["poses"].get<int>(), 2);
  auto cache = mesh_io::read_pc2(pc2);
  ASSERT_TRUE(cache.ok()) << cache.error().message;
  ASSERT_EQ(cache->num_frames(), 2);
  for (size_t p = 0; p < 2; ++p) {
    PointMatrix expected;
    as::evaluate(*model, poses[p], expected);
    ASSERT_EQ(cache->num_points, expected.rows());
    for (Eigen::Index v = 0; v < expected.rows(); ++v) {
      for (int c = 0; c < 3; ++c) {
        ASSERT_NEAR(cache->samples(static_cast<Eigen::Index>(p), 3 * v + c), expected(v, c), 1e-4f) << "pose " << p;
      }
    }
  }
  // A pose file that does not split into poses of this model is refused, naming the file.
  std::ofstream(work_->path() / "bad.txt") << "1 0 0 0 0 1 0 0 0 0 1\n";
  const CliRun bad = cli("pose arm-animspace --pose-file " + (work_->path() / "bad.txt").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("bad.txt: expected a multiple of"), std::string::npos) << bad.err;
}

TEST_F(CliClientTest, RpcFailuresExitWithTheStatusAndTheServersMessage) {
  const CliRun run = cli("keys no-such-model");
  EXPECT_EQ(run.exit_code, 3);
  EXPECT_NE(run.err.find("NOT_FOUND"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("no-such-model"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace animspace
