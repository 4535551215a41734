// Issue #6 over real gRPC against the real animspaced: the pose RPCs, precise refusals of bad
// requests, the miss → complete → retrain → hit cycle, hot swap under a running stream, miss-log
// recovery after kill -9, admission control and server fail-through. Expected values are computed
// here from the demo rig and the papers' formulas, never read back from the daemon.
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <thread>

#include <gtest/gtest.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/skinning.grpc.pb.h"
#include "animspace/v1/stats.grpc.pb.h"
#include "animspace/v1/training.grpc.pb.h"
#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/bending_arm.h"
#include "core/demo/demo_repository.h"
#include "core/lod/lod_io.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/train.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/metrics_scrape.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;
using testing::narrow_arm_model;
using testing::wait_until;
using testing::write_model;

constexpr double kDegree = 3.14159265358979323846 / 180.0;

Eigen::VectorXf decode(const v1::PointArray& array) {
  Eigen::VectorXf out(static_cast<Eigen::Index>(array.point_count()) * array.channel_count());
  EXPECT_EQ(array.data().size(), static_cast<size_t>(out.size()) * sizeof(float));
  std::memcpy(out.data(), array.data().data(), std::min(array.data().size(), static_cast<size_t>(out.size()) * 4));
  return out;
}

Eigen::VectorXf flatten(const PointMatrix& points) {
  return Eigen::Map<const Eigen::VectorXf>(points.data(), points.size());
}

// The key rows of a full frame, in the order DescribeKeyPoints lists them.
Eigen::VectorXf gather(const v1::DescribeKeyPointsResponse& keys, const Eigen::VectorXf& frame) {
  const long D = keys.channel_count();
  Eigen::VectorXf out(keys.key_point_indices_size() * D);
  for (int k = 0; k < keys.key_point_indices_size(); ++k) {
    out.segment(k * D, D) = frame.segment(static_cast<long>(keys.key_point_indices(k)) * D, D);
  }
  return out;
}

// The bending arm, posed by the expensive rig (biceps bulge and elbow correction included).
Eigen::VectorXf expensive_frame(double elbow_deg, double shoulder_deg) {
  static const demo::ArmRig rig = demo::make_arm_rig();
  return testing::expensive_arm_frame(rig, elbow_deg, shoulder_deg);
}

class ServeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    template_repo_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(template_repo_->path()).ok());
    write_model(template_repo_->path(), "bend", 1, narrow_arm_model());
  }
  static void TearDownTestSuite() {
    delete template_repo_;
    template_repo_ = nullptr;
  }

  void SetUp() override {
    repo_ = work_.path() / "repo";
    std::filesystem::copy(template_repo_->path(), repo_, std::filesystem::copy_options::recursive);
  }

  std::unique_ptr<DaemonProcess> start(std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--model-repository", repo_.string(), "--log-level", "info"};
    args.insert(args.end(), extra.begin(), extra.end());
    auto daemon = std::make_unique<DaemonProcess>(args, work_.path());
    Client client(daemon->address());
    EXPECT_TRUE(testing::wait_until_serving(client)) << "never SERVING";
    return daemon;
  }

  static std::shared_ptr<grpc::Channel> channel(const DaemonProcess& daemon) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(64 << 20);
    return grpc::CreateCustomChannel(daemon.address(), grpc::InsecureChannelCredentials(), args);
  }

  static v1::DescribeKeyPointsResponse describe_keys(v1::PoseService::Stub& poses, const std::string& model,
                                                     uint64_t version = 0) {
    grpc::ClientContext context;
    v1::DescribeKeyPointsRequest request;
    request.mutable_model()->set_name(model);
    request.mutable_model()->set_version(version);
    v1::DescribeKeyPointsResponse response;
    const auto status = poses.DescribeKeyPoints(&context, request, &response);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response;
  }

  static grpc::Status evaluate(v1::PoseService::Stub& poses, const v1::EvaluateKeyPointsRequest& request,
                               v1::EvaluateKeyPointsResponse* response) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    return poses.EvaluateKeyPoints(&context, request, response);
  }

  static v1::RetrainResponse retrain(v1::TrainingService::Stub& training, const std::string& model, bool dry_run,
                                     grpc::Status* status) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    v1::RetrainRequest request;
    request.mutable_model()->set_name(model);
    request.set_dry_run(dry_run);
    v1::RetrainResponse response;
    *status = training.Retrain(&context, request, &response);
    return response;
  }

  static inline TempDir* template_repo_ = nullptr;
  TempDir work_;
  std::filesystem::path repo_;
};

// ---------------------------------------------------------------------------------------------
// Bad requests: the exact status and the field each one names.

struct BadCase {
  const char* name;
  grpc::StatusCode code;
  std::string message_part;
  std::function<grpc::Status()> call;
};

TEST_F(ServeTest, BadRequestsGetTheExactStatusAndNameTheField) {
  // The demo arm's level count, which the LOD refusal names: read from the demo's own container.
  const int arm_levels = [] {
    auto container = demo::make_demo_animation_space_container();
    EXPECT_TRUE(container.ok());
    auto model = animation_space::load(*container, "arm");
    EXPECT_TRUE(model.ok());
    auto levels = lod::load_levels(*container, *model, "arm");
    EXPECT_TRUE(levels.ok());
    return levels.ok() ? levels->count() : 0;
  }();
  auto daemon = start({"--max-batch-poses", "4", "--max-message-bytes", "50000"});
  auto ch = channel(*daemon);
  auto poses = v1::PoseService::NewStub(ch);
  auto skinning = v1::SkinningService::NewStub(ch);
  auto training = v1::TrainingService::NewStub(ch);

  const auto keys = describe_keys(*poses, "arm-pmsc");
  const uint32_t K = static_cast<uint32_t>(keys.key_point_indices_size());
  // A training frame of the demo (frame 0 of its animation): a hit.
  const demo::ArmRig rig = demo::make_arm_rig();
  const Eigen::VectorXf full = flatten(demo::pose_expensive(demo::demo_animation(demo::kDemoFrames)[0], rig));
  const Eigen::VectorXf good = gather(keys, full);
  const auto N = static_cast<uint32_t>(full.size() / 3);
  ASSERT_GT(K, 3u);

  auto request_with = [&](const std::string& model, int pose_count, auto&& edit) {
    v1::EvaluateKeyPointsRequest request;
    request.mutable_model()->set_name(model);
    for (int i = 0; i < pose_count; ++i) {
      *request.add_poses()->mutable_key_values() = make_point_array(good.data(), K, 3);
    }
    edit(request);
    return request;
  };
  auto eval = [&](v1::EvaluateKeyPointsRequest request) {
    v1::EvaluateKeyPointsResponse response;
    return evaluate(*poses, request, &response);
  };
  auto no_edit = [](v1::EvaluateKeyPointsRequest&) {};
  const std::string k = std::to_string(K);

  std::vector<BadCase> cases = {
      {"empty model name", grpc::StatusCode::INVALID_ARGUMENT, "model.name is empty",
       [&] { return eval(request_with("", 1, no_edit)); }},
      {"path traversal", grpc::StatusCode::INVALID_ARGUMENT, "model.name '../arm-pmsc' starts with '.'",
       [&] { return eval(request_with("../arm-pmsc", 1, no_edit)); }},
      {"path separator", grpc::StatusCode::INVALID_ARGUMENT,
       "model.name may contain only letters, digits, '_', '-' and '.', got 'arm/../arm-pmsc'",
       [&] { return eval(request_with("arm/../arm-pmsc", 1, no_edit)); }},
      {"unknown model", grpc::StatusCode::NOT_FOUND, "model 'nosuch' is not loaded",
       [&] { return eval(request_with("nosuch", 1, no_edit)); }},
      {"unknown version", grpc::StatusCode::NOT_FOUND, "model 'arm-pmsc' has no servable version 99 (available: 1)",
       [&] { return eval(request_with("arm-pmsc", 1, [](auto& r) { r.mutable_model()->set_version(99); })); }},
      {"empty batch", grpc::StatusCode::INVALID_ARGUMENT, "poses: empty batch, expected 1..4 entries",
       [&] { return eval(request_with("arm-pmsc", 0, no_edit)); }},
      {"oversize batch", grpc::StatusCode::RESOURCE_EXHAUSTED, "poses: 5 entries, the limit is 4 (--max-batch-poses)",
       [&] { return eval(request_with("arm-pmsc", 5, no_edit)); }},
      {"wrong key point count", grpc::StatusCode::INVALID_ARGUMENT,
       "poses[1].key_values.point_count: expected " + k + " key points, got " + std::to_string(K - 1),
       [&] {
         return eval(request_with("arm-pmsc", 2, [&](auto& r) {
           *r.mutable_poses(1)->mutable_key_values() = make_point_array(good.data(), K - 1, 3);
         }));
       }},
      {"wrong channel count", grpc::StatusCode::INVALID_ARGUMENT, "poses[0].key_values.channel_count: expected 3, got 2",
       [&] {
         return eval(request_with("arm-pmsc", 1, [&](auto& r) {
           r.mutable_poses(0)->mutable_key_values()->set_channel_count(2);
         }));
       }},
      {"short data", grpc::StatusCode::INVALID_ARGUMENT,
       "poses[0].key_values.data: expected " + std::to_string(12 * K) + " bytes (4 · " + k + " · 3), got " +
           std::to_string(12 * K - 4),
       [&] {
         return eval(request_with("arm-pmsc", 1, [&](auto& r) {
           r.mutable_poses(0)->mutable_key_values()->mutable_data()->resize(12 * K - 4);
         }));
       }},
      {"NaN", grpc::StatusCode::INVALID_ARGUMENT,
       "poses[1].key_values.data: value of point 2, channel 1 is NaN; expected finite values",
       [&] {
         return eval(request_with("arm-pmsc", 2, [&](auto& r) {
           Eigen::VectorXf bad = good;
           bad[2 * 3 + 1] = std::numeric_limits<float>::quiet_NaN();
           *r.mutable_poses(1)->mutable_key_values() = make_point_array(bad.data(), K, 3);
         }));
       }},
      {"infinity", grpc::StatusCode::INVALID_ARGUMENT, "poses[0].key_values.data: value of point 0, channel 0 is infinite",
       [&] {
         return eval(request_with("arm-pmsc", 1, [&](auto& r) {
           Eigen::VectorXf bad = good;
           bad[0] = std::numeric_limits<float>::infinity();
           *r.mutable_poses(0)->mutable_key_values() = make_point_array(bad.data(), K, 3);
         }));
       }},
      {"oversize message", grpc::StatusCode::RESOURCE_EXHAUSTED, "",
       [&] {
         return eval(request_with("arm-pmsc", 1, [&](auto& r) {
           r.mutable_poses(0)->mutable_key_values()->mutable_data()->resize(300000);
         }));
       }},
      {"oversize response", grpc::StatusCode::RESOURCE_EXHAUSTED,
       "poses: the response to 4 entries would be about",
       [&] { return eval(request_with("arm-pmsc", 4, no_edit)); }},
      {"skeleton pose without a posing engine", grpc::StatusCode::INVALID_ARGUMENT,
       "poses[0].skeleton_pose: model 'arm-pmsc' has no posing engine on the server",
       [&] {
         return eval(request_with("arm-pmsc", 1, [&](auto& r) {
           *r.mutable_poses(0)->mutable_skeleton_pose() = testing::global_skeleton_pose({animation_space::Transform::Identity()});
         }));
       }},
      {"mesh sequence has no key points", grpc::StatusCode::FAILED_PRECONDITION,
       "model 'arm' version 1 is of kind mesh_sequence: it has no key points to evaluate",
       [&] { return eval(request_with("arm", 1, no_edit)); }},
      {"complete a cross-PMSC miss", grpc::StatusCode::FAILED_PRECONDITION, "is cross-PMSC",
       [&] {
         grpc::ClientContext context;
         v1::CompleteMissRequest request;
         request.mutable_model()->set_name("arm-cross-pmsc");
         v1::CompleteMissResponse response;
         return poses->CompleteMiss(&context, request, &response);
       }},
      {"complete with wrong full values", grpc::StatusCode::INVALID_ARGUMENT,
       "full_values.point_count: expected " + std::to_string(N) + " points, got 3",
       [&] {
         grpc::ClientContext context;
         v1::CompleteMissRequest request;
         request.mutable_model()->set_name("arm-pmsc");
         *request.mutable_key_values() = make_point_array(good.data(), K, 3);
         *request.mutable_full_values() = make_point_array(full.data(), 3, 3);
         v1::CompleteMissResponse response;
         return poses->CompleteMiss(&context, request, &response);
       }},
      {"describe keys of a skinning model", grpc::StatusCode::FAILED_PRECONDITION,
       "(evaluate it with SkinningService.EvaluateSkeletonPose)",
       [&] {
         grpc::ClientContext context;
         v1::DescribeKeyPointsRequest request;
         request.mutable_model()->set_name("arm-animspace");
         v1::DescribeKeyPointsResponse response;
         return poses->DescribeKeyPoints(&context, request, &response);
       }},
      {"skeleton pose on a model without skeleton", grpc::StatusCode::FAILED_PRECONDITION,
       "model 'arm-pmsc' version 1 is of kind pmsc and has no skeleton",
       [&] {
         grpc::ClientContext context;
         v1::EvaluateSkeletonPoseRequest request;
         request.mutable_model()->set_name("arm-pmsc");
         *request.add_poses() = testing::global_skeleton_pose({animation_space::Transform::Identity()});
         v1::EvaluateSkeletonPoseResponse response;
         return skinning->EvaluateSkeletonPose(&context, request, &response);
       }},
      {"wrong bone count", grpc::StatusCode::INVALID_ARGUMENT, "poses[0].bone_count: expected 3, got 1",
       [&] {
         grpc::ClientContext context;
         v1::EvaluateSkeletonPoseRequest request;
         request.mutable_model()->set_name("arm-animspace");
         *request.add_poses() = testing::global_skeleton_pose({animation_space::Transform::Identity()});
         v1::EvaluateSkeletonPoseResponse response;
         return skinning->EvaluateSkeletonPose(&context, request, &response);
       }},
      {"unspecified space", grpc::StatusCode::INVALID_ARGUMENT,
       "poses[0].space: expected SPACE_LOCAL or SPACE_GLOBAL, got 0",
       [&] {
         grpc::ClientContext context;
         v1::EvaluateSkeletonPoseRequest request;
         request.mutable_model()->set_name("arm-animspace");
         auto* pose = request.add_poses();
         *pose = testing::global_skeleton_pose(animation_space::TransformList(3, animation_space::Transform::Identity()));
         pose->set_space(v1::SkeletonPose::SPACE_UNSPECIFIED);
         v1::EvaluateSkeletonPoseResponse response;
         return skinning->EvaluateSkeletonPose(&context, request, &response);
       }},
      {"LOD level out of range", grpc::StatusCode::INVALID_ARGUMENT,
       "lod_level: expected 0.." + std::to_string(arm_levels - 1) + " (model 'arm-animspace' has " +
           std::to_string(arm_levels) + " levels), got 99",
       [&] {
         grpc::ClientContext context;
         v1::EvaluateSkeletonPoseRequest request;
         request.mutable_model()->set_name("arm-animspace");
         request.set_lod_level(99);
         *request.add_poses() = testing::global_skeleton_pose(animation_space::TransformList(3, animation_space::Transform::Identity()));
         v1::EvaluateSkeletonPoseResponse response;
         return skinning->EvaluateSkeletonPose(&context, request, &response);
       }},
      {"retrain a skinning model", grpc::StatusCode::FAILED_PRECONDITION, "model 'arm-animspace' version 1 is of kind animation_space: only PMSC subspaces are retrained",
       [&] {
         grpc::Status status;
         retrain(*training, "arm-animspace", true, &status);
         return status;
       }},
  };
  for (const auto& c : cases) {
    const grpc::Status status = c.call();
    EXPECT_EQ(status.error_code(), c.code) << c.name << ": " << status.error_message();
    EXPECT_NE(status.error_message().find(c.message_part), std::string::npos)
        << c.name << ": got \"" << status.error_message() << "\"";
  }

  // A bad frame in a stream ends it after the results before it, naming the frame's sequence.
  {
    grpc::ClientContext context;
    auto stream = poses->StreamKeyPoints(&context);
    for (uint64_t s : {5u, 6u, 7u}) {
      v1::KeyPointFrame frame;
      if (s == 5) frame.mutable_model()->set_name("arm-pmsc");
      frame.set_sequence(s);
      *frame.mutable_pose()->mutable_key_values() = make_point_array(good.data(), s == 7 ? K - 1 : K, 3);
      ASSERT_TRUE(stream->Write(frame));
    }
    stream->WritesDone();
    v1::PoseResult result;
    std::vector<uint64_t> answered;
    while (stream->Read(&result)) answered.push_back(result.sequence());
    const grpc::Status status = stream->Finish();
    EXPECT_EQ(answered, (std::vector<uint64_t>{5, 6}));
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("frame[sequence=7].pose.key_values.point_count: expected " + k), std::string::npos)
        << status.error_message();
  }
  {
    grpc::ClientContext context;
    auto stream = poses->StreamKeyPoints(&context);
    v1::KeyPointFrame frame;
    frame.set_sequence(0);
    ASSERT_TRUE(stream->Write(frame));
    stream->WritesDone();
    v1::PoseResult result;
    EXPECT_FALSE(stream->Read(&result));
    const grpc::Status status = stream->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("frame[sequence=0].model.name: the first frame must name the model"),
              std::string::npos)
        << status.error_message();
  }

  // Refused requests evaluated nothing and logged nothing: the two good stream frames are the
  // only poses arm-pmsc has seen, and they were a training pose (hits).
  Client client(daemon->address());
  const auto stats = client.stats("arm-pmsc");
  ASSERT_EQ(stats.models_size(), 1);
  EXPECT_EQ(stats.models(0).poses(), 2u);
  EXPECT_EQ(stats.models(0).misses() + stats.models(0).blends(), 0u);
  EXPECT_FALSE(std::filesystem::exists(repo_ / "arm-pmsc.misses"));
  // And the daemon is still serving.
  EXPECT_EQ(client.health(), grpc::health::v1::HealthCheckResponse::SERVING);
}

// ---------------------------------------------------------------------------------------------
// Miss → complete → retrain → hit: with the model file's sections held in memory (the default
// limit keeps this small model whole), and with every section left on disk and read from the
// file when asked (--resident-section-bytes 0, what a studio model's training frames get: issue
// #53), which must not change a single answer.

class ServeRetrainTest : public ServeTest, public ::testing::WithParamInterface<const char*> {};

INSTANTIATE_TEST_SUITE_P(SectionsInMemoryOrOnDisk, ServeRetrainTest, ::testing::Values("1048576", "0"));

TEST_P(ServeRetrainTest, AMissCompletedByTheClientIsLearnedByRetrainAndThenHits) {
  const int metrics_port = testing::free_tcp_port();
  auto daemon = start({"--metrics-listen", "127.0.0.1:" + std::to_string(metrics_port), "--resident-section-bytes",
                       GetParam()});
  auto ch = channel(*daemon);
  auto poses = v1::PoseService::NewStub(ch);
  auto training = v1::TrainingService::NewStub(ch);

  auto keys = describe_keys(*poses, "bend");
  EXPECT_EQ(keys.model_version(), 1u);
  EXPECT_EQ(keys.fail_through(), v1::FAIL_THROUGH_CLIENT);
  const Eigen::VectorXf bent = expensive_frame(120, 10);  // far outside elbow 0°–50°

  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name("bend");
  *request.add_poses()->mutable_key_values() = make_point_array(gather(keys, bent).data(), keys.key_point_indices_size(), 3);
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(evaluate(*poses, request, &response).ok());
  ASSERT_EQ(response.results_size(), 1);
  const auto& miss = response.results(0);
  EXPECT_EQ(miss.status(), v1::CACHE_STATUS_MISS) << "e_key " << miss.key_point_error();
  EXPECT_FLOAT_EQ(miss.blend_weight(), 1.0f);
  EXPECT_TRUE(miss.full_evaluation_needed());
  EXPECT_EQ(miss.model_version(), 1u);

  // The client computes the full pose and completes the miss: a miss returns f itself (α = 1).
  {
    grpc::ClientContext context;
    v1::CompleteMissRequest complete;
    complete.mutable_model()->set_name("bend");
    *complete.mutable_key_values() = request.poses(0).key_values();
    *complete.mutable_full_values() = make_point_array(bent.data(), static_cast<uint32_t>(bent.size() / 3), 3);
    v1::CompleteMissResponse completed;
    ASSERT_TRUE(poses->CompleteMiss(&context, complete, &completed).ok());
    EXPECT_TRUE(completed.logged());
    EXPECT_EQ(completed.result().status(), v1::CACHE_STATUS_MISS);
    EXPECT_FALSE(completed.result().full_evaluation_needed());
    EXPECT_EQ((decode(completed.result().points()) - bent).cwiseAbs().maxCoeff(), 0.0f);
  }

  grpc::Status status;
  const auto retrained = retrain(*training, "bend", false, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(retrained.new_version(), 2u);
  EXPECT_EQ(retrained.misses_used(), 1u);
  EXPECT_EQ(retrained.training_frames(), 34u);  // 11 elbow angles × 3 shoulder angles + the miss
  EXPECT_TRUE(std::filesystem::exists(repo_ / "bend" / "2" / "model.anim"));
  {
    // The response says what changed for the soft cache (issue #21): both versions' ε as their
    // files hold them, and each version's hit rate on the new training frames, counted here.
    auto old_file = container::read_file(repo_ / "bend" / "1" / "model.anim");
    auto new_file = container::read_file(repo_ / "bend" / "2" / "model.anim");
    ASSERT_TRUE(old_file.ok() && new_file.ok());
    auto old_model = pmsc::load(*old_file, "bend/1");
    auto new_model = pmsc::load(*new_file, "bend/2");
    ASSERT_TRUE(old_model.ok() && new_model.ok());
    EXPECT_FLOAT_EQ(retrained.previous_epsilon_min(), static_cast<float>(old_model->epsilon.epsilon_min));
    EXPECT_FLOAT_EQ(retrained.previous_epsilon_max(), static_cast<float>(old_model->epsilon.epsilon_max));
    EXPECT_FLOAT_EQ(retrained.epsilon_min(), static_cast<float>(new_model->epsilon.epsilon_min));
    EXPECT_FLOAT_EQ(retrained.epsilon_max(), static_cast<float>(new_model->epsilon.epsilon_max));
    auto frames = new_file->float_matrix(container::sections::kSequenceFrames);
    ASSERT_TRUE(frames.ok());
    auto hits_of = [&](const pmsc::PmscModel& model) {
      int hits = 0;
      pmsc::CachedPose cached;
      for (Eigen::Index f = 0; f < frames->rows(); ++f) {
        const Eigen::VectorXf frame = frames->row(f).transpose();
        pmsc::evaluate_cached(model, pmsc::gather_key_values(model, frame), nullptr, cached);
        hits += cached.status == pmsc::CacheStatus::kHit ? 1 : 0;
      }
      return static_cast<double>(hits) / static_cast<double>(frames->rows());
    };
    EXPECT_DOUBLE_EQ(retrained.previous_hit_rate(), hits_of(*old_model));
    EXPECT_DOUBLE_EQ(retrained.hit_rate(), hits_of(*new_model));
    EXPECT_EQ(retrained.misses_inconsistent(), 0u);
  }

  // Version 2 is now the default; its key points may differ, so the client asks again.
  keys = describe_keys(*poses, "bend");
  EXPECT_EQ(keys.model_version(), 2u);
  request.mutable_poses(0)->mutable_key_values()->CopyFrom(
      make_point_array(gather(keys, bent).data(), keys.key_point_indices_size(), 3));
  response.Clear();
  ASSERT_TRUE(evaluate(*poses, request, &response).ok());
  const auto& hit = response.results(0);
  EXPECT_EQ(hit.status(), v1::CACHE_STATUS_HIT) << "e_key " << hit.key_point_error();
  EXPECT_EQ(hit.model_version(), 2u);
  const double diagonal = pmsc::bounding_box_diagonal(bent);
  const Eigen::VectorXf estimate = decode(hit.points());
  double worst = 0;
  for (long i = 0; i < bent.size() / 3; ++i) worst = std::max(worst, double((estimate - bent).segment(3 * i, 3).norm()));
  EXPECT_LT(worst, 0.01 * diagonal) << "the learned pose must be reproduced within the 1% tolerance";

  // Version 1 still answers when named (calls that pinned it keep working) — and still misses.
  const auto keys_v1 = describe_keys(*poses, "bend", 1);
  request.mutable_model()->set_version(1);
  *request.mutable_poses(0)->mutable_key_values() =
      make_point_array(gather(keys_v1, bent).data(), keys_v1.key_point_indices_size(), 3);
  response.Clear();
  ASSERT_TRUE(evaluate(*poses, request, &response).ok());
  EXPECT_EQ(response.results(0).model_version(), 1u);
  EXPECT_EQ(response.results(0).status(), v1::CACHE_STATUS_MISS);

  // Statistics and Prometheus agree: two misses (CompleteMiss is not another pose), one hit.
  Client client(daemon->address());
  const auto stats = client.stats("bend");
  EXPECT_EQ(stats.models(0).poses(), 3u);
  EXPECT_EQ(stats.models(0).misses(), 2u);
  EXPECT_EQ(stats.models(0).hits(), 1u);
  EXPECT_DOUBLE_EQ(stats.models(0).hit_rate(), 1.0 / 3.0);
  const auto scraped = testing::scrape_metrics(metrics_port);
  ASSERT_TRUE(scraped);
  EXPECT_NE(scraped->find("animspace_cache_misses_total{model=\"bend\"} 2\n"), std::string::npos);
  EXPECT_NE(scraped->find("animspace_cache_hits_total{model=\"bend\"} 1\n"), std::string::npos);
  EXPECT_NE(scraped->find("animspace_model_version_serving{model=\"bend\",version=\"2\",default=\"1\"} 1\n"),
            std::string::npos);
  EXPECT_NE(scraped->find("animspace_requests_total{rpc=\"TrainingService/Retrain\",model=\"bend\",code=\"OK\"} 1\n"),
            std::string::npos);

  // A second retrain finds only the version-1 miss just logged (without full values: nothing to
  // learn); the first one's miss is already in version 2's frames.
  const auto again = retrain(*training, "bend", true, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(again.misses_used(), 0u);
  EXPECT_EQ(again.training_frames(), 34u);
  EXPECT_EQ(again.new_version(), 0u);  // dry run
  // Nothing new and no option changed: the dry run says so, and what it trained is version 2
  // again — the same thresholds and the same hit rate on the same frames.
  EXPECT_TRUE(again.unchanged());
  EXPECT_EQ(again.epsilon_min(), again.previous_epsilon_min());
  EXPECT_EQ(again.epsilon_max(), again.previous_epsilon_max());
  EXPECT_EQ(again.hit_rate(), again.previous_hit_rate());
  // So a retrain that would publish it is refused, saying why, and no version 3 appears.
  const auto refused = retrain(*training, "bend", false, &status);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << status.error_message();
  EXPECT_NE(status.error_message().find("version 2: nothing new to train on"), std::string::npos)
      << status.error_message();
  EXPECT_NE(status.error_message().find("(1 logged without them"), std::string::npos) << status.error_message();
  EXPECT_FALSE(std::filesystem::exists(repo_ / "bend" / "3"));
  EXPECT_EQ(describe_keys(*poses, "bend").model_version(), 2u);
  // A changed option is something new.
  {
    grpc::ClientContext context;
    v1::RetrainRequest other_budget;
    other_budget.mutable_model()->set_name("bend");
    other_budget.set_dry_run(true);
    other_budget.set_max_key_points(static_cast<uint32_t>(keys.key_point_indices_size()) + 5);
    v1::RetrainResponse reported;
    ASSERT_TRUE(training->Retrain(&context, other_budget, &reported).ok());
    EXPECT_FALSE(reported.unchanged());
  }
}

// ---------------------------------------------------------------------------------------------
// Hot swap: a retrain publishes a new version while a client streams 1,000 poses.

TEST_F(ServeTest, HotSwapWhileStreamingAThousandPosesFailsNothing) {
  auto daemon = start();
  auto ch = channel(*daemon);
  auto poses = v1::PoseService::NewStub(ch);
  auto training = v1::TrainingService::NewStub(ch);
  const auto keys = describe_keys(*poses, "arm-pmsc");
  const auto K = static_cast<uint32_t>(keys.key_point_indices_size());

  // The demo animation's frames, looped.
  const demo::ArmRig rig = demo::make_arm_rig();
  std::vector<Eigen::VectorXf> key_frames;
  for (const auto& pose : demo::demo_animation(demo::kDemoFrames)) {
    key_frames.push_back(gather(keys, flatten(demo::pose_expensive(pose, rig))));
  }

  constexpr int kFrames = 1000;
  grpc::ClientContext context;
  auto stream = poses->StreamKeyPoints(&context);
  std::atomic<int> received{0};
  std::atomic<bool> swapped{false};
  std::thread writer([&] {
    for (int s = 0; s < kFrames; ++s) {
      // The second half goes out only after the new version is serving.
      if (s == kFrames / 2) swapped.wait(false);
      v1::KeyPointFrame frame;
      if (s == 0) frame.mutable_model()->set_name("arm-pmsc");
      frame.set_sequence(static_cast<uint64_t>(s));
      frame.set_omit_points(s % 2 == 1);
      *frame.mutable_pose()->mutable_key_values() = make_point_array(key_frames[s % key_frames.size()].data(), K, 3);
      if (!stream->Write(frame)) break;
    }
    stream->WritesDone();
  });
  std::vector<v1::PoseResult> results;
  std::thread reader([&] {
    v1::PoseResult result;
    while (stream->Read(&result)) {
      results.push_back(result);
      received.fetch_add(1);
    }
  });
  // Not ASSERT: the writer and reader threads must be released and joined whatever happens.
  EXPECT_TRUE(wait_until([&] { return received.load() >= 100; })) << "the stream never got going";
  // Nothing was logged, so the retrain changes an option (a larger key budget) to be something new
  // to publish rather than a copy, which is refused.
  grpc::Status retrain_status;
  v1::RetrainResponse retrained;
  {
    grpc::ClientContext retrain_context;
    retrain_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    v1::RetrainRequest request;
    request.mutable_model()->set_name("arm-pmsc");
    request.set_max_key_points(K + 4);
    retrain_status = training->Retrain(&retrain_context, request, &retrained);
  }
  const int received_at_swap = received.load();
  swapped.store(true);
  swapped.notify_all();
  writer.join();
  reader.join();
  const grpc::Status status = stream->Finish();

  ASSERT_TRUE(retrain_status.ok()) << retrain_status.error_message();
  EXPECT_EQ(retrained.new_version(), 2u);
  EXPECT_LT(received_at_swap, kFrames) << "the swap must happen while the stream runs";
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(results.size(), static_cast<size_t>(kFrames));
  for (int s = 0; s < kFrames; ++s) {
    EXPECT_EQ(results[s].sequence(), static_cast<uint64_t>(s));
    // The stream pinned the version it started on.
    EXPECT_EQ(results[s].model_version(), 1u);
    EXPECT_EQ(results[s].has_points(), s % 2 == 0);
  }
  // New calls get the new version.
  EXPECT_EQ(describe_keys(*poses, "arm-pmsc").model_version(), 2u);
}

// ---------------------------------------------------------------------------------------------
// kill -9 while misses are being appended: every acknowledged record survives the restart.

TEST_F(ServeTest, KillNineMidAppendKeepsEveryCompleteMissRecord) {
  std::atomic<int> acknowledged{0};
  std::atomic<int> attempted{0};
  {
    auto daemon = start({"--miss-log-fsync", "never"});
    auto ch = channel(*daemon);
    auto poses = v1::PoseService::NewStub(ch);
    const auto keys = describe_keys(*poses, "bend");
    std::atomic<bool> stop{false};
    std::vector<std::thread> clients;
    for (int t = 0; t < 3; ++t) {
      clients.emplace_back([&, t] {
        auto stub = v1::PoseService::NewStub(ch);
        for (int i = 0; !stop.load(); ++i) {
          const Eigen::VectorXf full = expensive_frame(100 + (i % 40), 10.0 * t);
          grpc::ClientContext context;
          context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
          v1::CompleteMissRequest request;
          request.mutable_model()->set_name("bend");
          *request.mutable_key_values() = make_point_array(gather(keys, full).data(), keys.key_point_indices_size(), 3);
          *request.mutable_full_values() = make_point_array(full.data(), static_cast<uint32_t>(full.size() / 3), 3);
          v1::CompleteMissResponse response;
          attempted.fetch_add(1);
          if (stub->CompleteMiss(&context, request, &response).ok() && response.logged()) acknowledged.fetch_add(1);
        }
      });
    }
    EXPECT_TRUE(wait_until([&] { return acknowledged.load() >= 30; })) << "misses were never acknowledged";
    daemon->send_signal(SIGKILL);
    EXPECT_NE(daemon->wait_for_exit(std::chrono::seconds(10)), -1);
    stop.store(true);
    for (auto& client : clients) client.join();
  }
  // Whatever the kill left, add a torn record on top: the header of a record whose payload
  // never made it to disk.
  const auto log = repo_ / "bend.misses";
  ASSERT_TRUE(std::filesystem::exists(log));
  {
    std::ofstream torn(log, std::ios::binary | std::ios::app);
    const char partial[] = {'\x4d', '\x49', '\x53', '\x53', '\x00', '\x10', '\x00', '\x00', '\x01'};
    torn.write(partial, sizeof(partial));
  }

  auto daemon = start();
  auto training = v1::TrainingService::NewStub(channel(*daemon));
  grpc::Status status;
  const auto dry = retrain(*training, "bend", true, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_GE(dry.misses_used(), static_cast<uint32_t>(acknowledged.load()));
  EXPECT_LE(dry.misses_used(), static_cast<uint32_t>(attempted.load()));

  // The recovered log takes new records after the surviving ones.
  auto poses = v1::PoseService::NewStub(channel(*daemon));
  const auto keys = describe_keys(*poses, "bend");
  const Eigen::VectorXf full = expensive_frame(150, 0);
  grpc::ClientContext context;
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name("bend");
  *request.mutable_key_values() = make_point_array(gather(keys, full).data(), keys.key_point_indices_size(), 3);
  *request.mutable_full_values() = make_point_array(full.data(), static_cast<uint32_t>(full.size() / 3), 3);
  v1::CompleteMissResponse response;
  ASSERT_TRUE(poses->CompleteMiss(&context, request, &response).ok());
  EXPECT_TRUE(response.logged());
  const auto after = retrain(*training, "bend", true, &status);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(after.misses_used(), dry.misses_used() + 1);
}

// ---------------------------------------------------------------------------------------------
// Admission: beyond --max-concurrent-calls a call is refused at once, not queued.

TEST_F(ServeTest, CallsBeyondTheConcurrencyLimitAreRefusedAtOnce) {
  auto daemon = start({"--max-concurrent-calls", "1"});
  auto ch = channel(*daemon);
  auto poses = v1::PoseService::NewStub(ch);
  Client client(daemon->address());

  v1::DescribeKeyPointsResponse keys;
  const auto keys_probe = [&] {
    grpc::ClientContext context;
    v1::DescribeKeyPointsRequest request;
    request.mutable_model()->set_name("arm-pmsc");
    return poses->DescribeKeyPoints(&context, request, &keys);
  };
  ASSERT_TRUE(keys_probe().ok());  // the slot is free: K, for the stream's frame
  const int K = keys.key_point_indices_size();

  // An open stream holds the one slot. It is known to hold it once it has answered a frame: a
  // probe sent before that could take the slot first, and the stream would be the call refused.
  grpc::ClientContext stream_context;
  auto stream = poses->StreamKeyPoints(&stream_context);
  v1::KeyPointFrame frame;
  frame.mutable_model()->set_name("arm-pmsc");
  frame.set_sequence(1);
  const std::vector<float> origin(static_cast<size_t>(3 * K), 0.0f);
  *frame.mutable_pose()->mutable_key_values() = make_point_array(origin.data(), static_cast<uint32_t>(K), 3);
  ASSERT_TRUE(stream->Write(frame));
  v1::PoseResult first;
  ASSERT_TRUE(stream->Read(&first)) << "the stream was refused: " << stream->Finish().error_message();
  // Refused while the stream still holds the slot, so it did not wait for one.
  const grpc::Status refused = keys_probe();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(refused.error_message().find("server busy: 1 calls are already in progress (--max-concurrent-calls)"),
            std::string::npos)
      << refused.error_message();

  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  // Load gone: served again.
  grpc::Status served;
  wait_until([&] { return (served = keys_probe()).ok(); }, std::chrono::seconds(30), std::chrono::milliseconds(5));
  EXPECT_TRUE(served.ok()) << served.error_message();
}

// ---------------------------------------------------------------------------------------------
// Server fail-through and skeleton evaluation, against the demo model evaluated here.

TEST_F(ServeTest, ServerFailThroughAndSkeletonPosesMatchTheAnimationSpaceModel) {
  auto daemon = start();
  auto ch = channel(*daemon);
  auto poses = v1::PoseService::NewStub(ch);
  auto skinning = v1::SkinningService::NewStub(ch);

  auto container = container::read_file(repo_ / "arm-pmsc-engine" / "1" / "model.anim");
  ASSERT_TRUE(container.ok());
  auto engine = animation_space::load(*container, "arm-pmsc-engine");
  ASSERT_TRUE(engine.ok()) << engine.error().message;

  // A pose far outside the demo animation: the forearm folded back, the upper arm raised.
  const demo::ArmRig rig = demo::make_arm_rig();
  demo::ArmPose far;
  far.elbow_angle_rad = 160 * kDegree;
  far.shoulder_angle_rad = 100 * kDegree;
  far.forearm_twist_rad = 60 * kDegree;
  const auto G = demo::bone_transforms(far, rig.options);
  const animation_space::TransformList globals{animation_space::Transform::Identity(), G[demo::kUpperArm],
                                               G[demo::kForearm]};
  PointMatrix posed;
  animation_space::evaluate(*engine, globals, posed);
  const Eigen::VectorXf full = flatten(posed);

  const auto keys = describe_keys(*poses, "arm-pmsc-engine");
  EXPECT_EQ(keys.fail_through(), v1::FAIL_THROUGH_SERVER);
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name("arm-pmsc-engine");
  auto* pose = request.add_poses();
  *pose->mutable_key_values() = make_point_array(gather(keys, full).data(), keys.key_point_indices_size(), 3);
  *pose->mutable_skeleton_pose() = testing::global_skeleton_pose(globals);
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(evaluate(*poses, request, &response).ok());
  const auto& result = response.results(0);
  ASSERT_EQ(result.status(), v1::CACHE_STATUS_MISS) << "e_key " << result.key_point_error();
  EXPECT_FALSE(result.full_evaluation_needed());
  // A miss returns the full calculation: the engine's pose (float transforms on the wire).
  const double diagonal = pmsc::bounding_box_diagonal(full);
  EXPECT_LT((decode(result.points()) - full).cwiseAbs().maxCoeff(), 1e-5 * diagonal);

  // The same pose through SkinningService, at full detail and at LOD level 3.
  grpc::ClientContext context;
  v1::EvaluateSkeletonPoseRequest skin;
  skin.mutable_model()->set_name("arm-animspace");
  skin.set_include_normals(true);
  *skin.add_poses() = testing::global_skeleton_pose(globals);
  v1::EvaluateSkeletonPoseResponse skinned;
  ASSERT_TRUE(skinning->EvaluateSkeletonPose(&context, skin, &skinned).ok());
  auto animspace_container = container::read_file(repo_ / "arm-animspace" / "1" / "model.anim");
  ASSERT_TRUE(animspace_container.ok());
  auto animspace_model = animation_space::load(*animspace_container, "arm-animspace");
  ASSERT_TRUE(animspace_model.ok());
  animation_space::evaluate(*animspace_model, globals, posed);
  EXPECT_LT((decode(skinned.poses(0).points()) - flatten(posed)).cwiseAbs().maxCoeff(), 1e-5 * diagonal);
  const Eigen::VectorXf normals = decode(skinned.poses(0).normals());
  for (long i = 0; i < normals.size() / 3; ++i) EXPECT_NEAR(normals.segment(3 * i, 3).norm(), 1.0, 1e-4);

  // Local fail-through: the engine poses only the points the server names; every other point is
  // the estimate f̂, computed here from the model file.
  request.set_local_fail_through(true);
  ASSERT_TRUE(evaluate(*poses, request, &response).ok());
  const auto& local = response.results(0);
  EXPECT_EQ(local.status(), v1::CACHE_STATUS_MISS);
  EXPECT_FALSE(local.full_evaluation_needed());
  ASSERT_GT(local.full_points_size(), 0);
  ASSERT_EQ(local.full_point_blend_weights_size(), local.full_points_size());
  auto pmsc_model = pmsc::load(*container, "arm-pmsc-engine");
  ASSERT_TRUE(pmsc_model.ok()) << pmsc_model.error().message;
  pmsc::PoseEstimate estimate;
  pmsc::evaluate(*pmsc_model, gather(keys, full), estimate);
  const Eigen::VectorXf answer = decode(local.points());
  Eigen::VectorXf expected = estimate.points;
  for (int j = 0; j < local.full_points_size(); ++j) {
    const long i = local.full_points(j);
    const float alpha = local.full_point_blend_weights(j);
    if (j > 0) {
      EXPECT_GT(local.full_points(j), local.full_points(j - 1));
    }
    expected.segment(3 * i, 3) = alpha * full.segment(3 * i, 3) + (1 - alpha) * estimate.points.segment(3 * i, 3);
  }
  EXPECT_LT((answer - expected).cwiseAbs().maxCoeff(), 1e-5 * diagonal);
  // The miss log holds what the engine computed: a partial frame of exactly those points.
  auto records = misslog::read_records(repo_ / "arm-pmsc-engine.misses", 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  ASSERT_EQ(records->size(), 2u);  // the whole-pose miss above, then this one
  EXPECT_TRUE(records->front().full_points.empty());
  ASSERT_EQ(records->back().full_points.size(), static_cast<size_t>(local.full_points_size()));
  for (int j = 0; j < local.full_points_size(); ++j) {
    const uint32_t i = local.full_points(j);
    EXPECT_EQ(records->back().full_points[static_cast<size_t>(j)], i);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(records->back().full_values[static_cast<size_t>(3 * j + c)], full(3 * i + c), 1e-5 * diagonal);
    }
  }

  auto levels = lod::load_levels(*animspace_container, *animspace_model, "arm-animspace");
  ASSERT_TRUE(levels.ok());
  grpc::ClientContext lod_context;
  skin.set_lod_level(3);
  skin.set_include_normals(false);
  ASSERT_TRUE(skinning->EvaluateSkeletonPose(&lod_context, skin, &skinned).ok());
  animation_space::evaluate(levels->levels[3].model, globals, posed);
  EXPECT_EQ(skinned.poses(0).points().point_count(), static_cast<uint32_t>(levels->levels[3].model.vertex_count()));
  EXPECT_LT((decode(skinned.poses(0).points()) - flatten(posed)).cwiseAbs().maxCoeff(), 1e-5 * diagonal);
}

}  // namespace
}  // namespace animspace

namespace animspace {
namespace {

// ---------------------------------------------------------------------------------------------
// The repository poll picks up new versions; an unloaded model stays unloaded.

TEST_F(ServeTest, PollingLoadsNewVersionsAndRespectsUnloads) {
  auto daemon = start({"--poll-interval-s", "0.1"});
  Client client(daemon->address());
  EXPECT_EQ(client.describe_model("arm-pmsc").default_version(), 1u);

  // Publish a version the way a nightly job should: write it aside, rename it into place; the
  // poll serves it.
  const auto publish = [&](uint64_t version) {
    const auto staging = repo_ / "arm-pmsc" / ".staging";
    std::filesystem::create_directories(staging);
    std::filesystem::copy_file(repo_ / "arm-pmsc" / "1" / "model.anim", staging / "model.anim");
    std::filesystem::rename(staging, repo_ / "arm-pmsc" / std::to_string(version));
    uint64_t served = 0;
    EXPECT_TRUE(wait_until([&] { return (served = client.describe_model("arm-pmsc").default_version()) == version; },
                           std::chrono::seconds(30)))
        << "version " << version << " never served; default " << served;
  };
  publish(2);

  // After the unload, two more versions served one after the other prove that a whole poll ran
  // after it: the poll that serves version 4 began after version 3 was served. A poll that
  // brought the unloaded model back would have done so by then.
  client.unload_model("arm-cross-pmsc");
  publish(3);
  publish(4);
  try {
    client.describe_model("arm-cross-pmsc");
    ADD_FAILURE() << "the poll brought back a model unloaded on purpose";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::NOT_FOUND);
  }
  // LoadModel brings it back.
  EXPECT_EQ(client.load_model("arm-cross-pmsc").default_version(), 1u);
}

}  // namespace
}  // namespace animspace

namespace animspace {
namespace {

// ---------------------------------------------------------------------------------------------
// Deadlines: a call whose deadline passes while it waits for a worker is never started.

TEST_F(ServeTest, ACallWhoseDeadlinePassedInTheQueueIsNeverStarted) {
  const int metrics_port = testing::free_tcp_port();
  auto daemon = start({"--metrics-listen", "127.0.0.1:" + std::to_string(metrics_port)});
  auto ch = channel(*daemon);
  auto training = v1::TrainingService::NewStub(ch);
  // A version 2 of arm-pmsc on disk that only an explicit LoadModel would load (no polling).
  std::filesystem::create_directories(repo_ / "arm-pmsc" / "2");
  std::filesystem::copy_file(repo_ / "arm-pmsc" / "1" / "model.anim", repo_ / "arm-pmsc" / "2" / "model.anim");

  // Occupy the admin thread with eight retrains (dry runs: nothing published), wait until the
  // server holds most of them, then queue a LoadModel whose deadline, twice one retrain (timed
  // first), is far shorter than the work ahead of it yet long enough to reach the server: a fixed
  // 5 ms expired on the way under ThreadSanitizer, before the service ever saw the call.
  const auto timed = std::chrono::steady_clock::now();
  {
    grpc::Status status;
    retrain(*training, "bend", true, &status);
    ASSERT_TRUE(status.ok()) << status.error_message();
  }
  const auto one_retrain = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - timed);
  const auto deadline = std::clamp(2 * one_retrain, std::chrono::milliseconds(20), std::chrono::milliseconds(10000));
  const auto calls_in_flight = [metrics_port] {
    const auto page = testing::scrape_metrics(metrics_port);
    return page ? testing::metric_value(*page, "animspace_calls_in_flight").value_or(-1) : -1;
  };
  constexpr int kRetrains = 8;
  std::vector<std::thread> retrains;
  for (int r = 0; r < kRetrains; ++r) {
    retrains.emplace_back([&, model = r % 2 == 0 ? "bend" : "arm-pmsc-engine"] {
      grpc::Status status;
      retrain(*training, model, true, &status);
      EXPECT_TRUE(status.ok()) << status.error_message();
    });
  }
  // Six of eight in flight: at least four retrains wait behind the running one, twice the deadline.
  const bool queued = wait_until([&] { return calls_in_flight() >= kRetrains - 2; }, std::chrono::seconds(60),
                                  std::chrono::milliseconds(10));
  // Not ASSERT: the retrain threads must be joined either way.
  EXPECT_TRUE(queued) << "the retrains never reached the server";
  auto models = v1::ModelService::NewStub(ch);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + deadline);
  v1::LoadModelRequest load;
  load.mutable_model()->set_name("arm-pmsc");
  load.mutable_model()->set_version(2);
  v1::LoadModelResponse loaded;
  EXPECT_EQ(models->LoadModel(&context, load, &loaded).error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  for (auto& thread : retrains) thread.join();

  // The server dropped the call unstarted: version 2 was never loaded, and the call was counted
  // as cancelled or past its deadline.
  Client client(daemon->address());
  const auto arm = client.describe_model("arm-pmsc");
  EXPECT_EQ(arm.default_version(), 1u);
  EXPECT_EQ(arm.versions_size(), 1);
  // The dropped call is counted when the admin thread reaches it, just after the retrains.
  std::string body;
  const auto load_model_calls = [&body](const char* code) {
    return testing::metric_value(body, std::string("animspace_requests_total{rpc=\"ModelService/LoadModel\",model=\"\",code=\"") +
                                           code + "\"}")
        .value_or(0);
  };
  // A generous deadline: under a sanitizer the four retrains ahead of it take many seconds.
  const bool dropped = wait_until(
      [&] {
        body = testing::scrape_metrics(metrics_port).value_or("");
        return load_model_calls("DEADLINE_EXCEEDED") + load_model_calls("CANCELLED") == 1;
      },
      std::chrono::seconds(60), std::chrono::milliseconds(10));
  EXPECT_EQ(client.describe_model("arm-pmsc").versions_size(), 1);
  EXPECT_TRUE(dropped) << body.substr(0, 4000);
}

}  // namespace
}  // namespace animspace
