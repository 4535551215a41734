// PoseService and the admin side of ModelService/StatsService in process (tests/server/support):
// the refusals a client gets for a bad EvaluateKeyPoints request, each naming the field, and the
// access an RPC needs decided from its request (GetStats with reset is an admin call) — checks
// the integration suite also makes against a daemon process (tests/integration/serve_test.cpp,
// security_test.cpp), here without one.
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "animspace/v1/stats.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "core/common/sha256.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_io.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::InProcessServer;
using testing::TempDir;
using Code = grpc::StatusCode;

const std::string kPmsc(demo::kDemoPmscModelName);

class PoseAndModelServiceTest : public testing::SmallRepositoryTest {
 protected:
  void serve(server::ServerOptions options = {}) {
    options.miss_log_dir = work_.path();
    server_ = std::make_unique<InProcessServer>(repository(), options);
    poses_ = v1::PoseService::NewStub(server_->channel());
  }

  // DescribeKeyPoints of the demo's PMSC model (OK asserted by the caller through `status`).
  v1::DescribeKeyPointsResponse describe_keys(grpc::Status* status) {
    grpc::ClientContext context;
    v1::DescribeKeyPointsRequest request;
    request.mutable_model()->set_name(kPmsc);
    v1::DescribeKeyPointsResponse keys;
    *status = poses_->DescribeKeyPoints(&context, request, &keys);
    return keys;
  }

  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
};

v1::PointArray point_array(const std::vector<float>& values, uint32_t count, uint32_t channels) {
  v1::PointArray a;
  a.set_point_count(count);
  a.set_channel_count(channels);
  a.set_data(values.data(), values.size() * sizeof(float));
  return a;
}

TEST_F(PoseAndModelServiceTest, BadKeyPointRequestsAreRefusedNamingTheField) {
  server::ServerOptions options;
  options.max_batch_poses = 4;
  serve(options);
  grpc::Status described;
  const v1::DescribeKeyPointsResponse keys = describe_keys(&described);
  ASSERT_TRUE(described.ok()) << described.error_message();
  const auto K = static_cast<uint32_t>(keys.key_point_indices_size());
  ASSERT_GT(K, 3u);
  const std::vector<float> good(size_t{K} * 3, 0.5f);
  const std::string k = std::to_string(K);

  const auto request_with = [&](const std::string& model, int poses,
                                const std::function<void(v1::EvaluateKeyPointsRequest&)>& edit) {
    v1::EvaluateKeyPointsRequest r;
    r.mutable_model()->set_name(model);
    for (int i = 0; i < poses; ++i) *r.add_poses()->mutable_key_values() = point_array(good, K, 3);
    edit(r);
    return r;
  };
  const auto none = [](v1::EvaluateKeyPointsRequest&) {};
  const auto with_bad_value = [&](int pose, size_t at, float value) {
    return [&good, K, pose, at, value](v1::EvaluateKeyPointsRequest& r) {
      std::vector<float> bad = good;
      bad[at] = value;
      *r.mutable_poses(pose)->mutable_key_values() = point_array(bad, K, 3);
    };
  };
  struct Case {
    std::string name;
    v1::EvaluateKeyPointsRequest request;
    Code code;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"empty model name", request_with("", 1, none), Code::INVALID_ARGUMENT, "model.name is empty"},
      {"path traversal", request_with("../arm-pmsc", 1, none), Code::INVALID_ARGUMENT,
       "model.name '../arm-pmsc' starts with '.'"},
      {"unknown model", request_with("nosuch", 1, none), Code::NOT_FOUND, "model 'nosuch' is not loaded"},
      {"unknown version",
       request_with(kPmsc, 1, [](v1::EvaluateKeyPointsRequest& r) { r.mutable_model()->set_version(99); }),
       Code::NOT_FOUND, "model 'arm-pmsc' has no servable version 99 (available: 1)"},
      {"empty batch", request_with(kPmsc, 0, none), Code::INVALID_ARGUMENT,
       "poses: empty batch, expected 1..4 entries"},
      {"oversize batch", request_with(kPmsc, 5, none), Code::RESOURCE_EXHAUSTED,
       "poses: 5 entries, the limit is 4 (--max-batch-poses)"},
      {"wrong key point count",
       request_with(kPmsc, 2,
                    [&](v1::EvaluateKeyPointsRequest& r) {
                      *r.mutable_poses(1)->mutable_key_values() = point_array(good, K - 1, 3);
                    }),
       Code::INVALID_ARGUMENT,
       "poses[1].key_values.point_count: expected " + k + " key points, got " + std::to_string(K - 1)},
      {"NaN", request_with(kPmsc, 2, with_bad_value(1, 2 * 3 + 1, std::numeric_limits<float>::quiet_NaN())),
       Code::INVALID_ARGUMENT, "poses[1].key_values.data: value of point 2, channel 1 is NaN"},
      {"infinity", request_with(kPmsc, 1, with_bad_value(0, 0, std::numeric_limits<float>::infinity())),
       Code::INVALID_ARGUMENT, "poses[0].key_values.data: value of point 0, channel 0 is infinite"},
      {"mesh sequence", request_with(std::string(demo::kDemoModelName), 1, none), Code::FAILED_PRECONDITION,
       "model 'arm' version 1 is of kind mesh_sequence: it has no key points to evaluate"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    grpc::ClientContext context;
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = poses_->EvaluateKeyPoints(&context, c.request, &response);
    EXPECT_EQ(status.error_code(), c.code) << status.error_message();
    EXPECT_NE(status.error_message().find(c.message), std::string::npos) << status.error_message();
  }
  // A bad batch counts no poses (every pose is checked before any is evaluated).
  const auto stats = server_->environment().metrics.model_statistics();
  const auto it = stats.find(kPmsc);
  EXPECT_TRUE(it == stats.end() || it->second.poses == 0);
}

TEST_F(PoseAndModelServiceTest, ResettingStatisticsNeedsAnAdminTokenReadingThemDoesNot) {
  testing::write_text_file(work_ / "user-tokens", "user-secret\n");
  testing::write_text_file(work_ / "admin-tokens", "admin-secret\n");
  server::ServerOptions options;
  options.auth_token_file = work_ / "user-tokens";
  options.admin_token_file = work_ / "admin-tokens";
  serve(options);
  auto stats = v1::StatsService::NewStub(server_->channel());
  const auto get_stats = [&](const std::string& token, bool reset) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    v1::GetStatsRequest request;
    request.set_reset(reset);
    v1::GetStatsResponse response;
    return stats->GetStats(&context, request, &response).error_code();
  };
  EXPECT_EQ(get_stats("user-secret", false), Code::OK);
  EXPECT_EQ(get_stats("user-secret", true), Code::PERMISSION_DENIED);
  EXPECT_EQ(get_stats("admin-secret", true), Code::OK);
  EXPECT_EQ(get_stats("wrong", false), Code::UNAUTHENTICATED);
}

TEST_F(PoseAndModelServiceTest, UnloadedModelsAreRefusedAndListedNoMore) {
  serve();
  auto models = v1::ModelService::NewStub(server_->channel());
  {
    grpc::ClientContext context;
    v1::UnloadModelRequest request;
    request.mutable_model()->set_name(kPmsc);
    v1::UnloadModelResponse response;
    ASSERT_TRUE(models->UnloadModel(&context, request, &response).ok());
  }
  grpc::ClientContext context;
  v1::DescribeKeyPointsRequest request;
  request.mutable_model()->set_name(kPmsc);
  v1::DescribeKeyPointsResponse keys;
  EXPECT_EQ(poses_->DescribeKeyPoints(&context, request, &keys).error_code(), Code::NOT_FOUND);
  grpc::ClientContext list_context;
  v1::ListModelsResponse list;
  ASSERT_TRUE(models->ListModels(&list_context, v1::ListModelsRequest(), &list).ok());
  for (const auto& model : list.models()) {
    if (model.name() != kPmsc) continue;
    for (const auto& version : model.versions())
      EXPECT_NE(version.state(), v1::VERSION_STATE_AVAILABLE) << "still serving";
  }
}

// A miss log created before partial frames (format version 2) cannot hold one: the server logs
// the frame retraining would complete — the computed points, the key values at the key points,
// the estimate f̂ elsewhere — as a whole frame, in the log's own version.
TEST_F(PoseAndModelServiceTest, PartialFramesReachAnOldMissLogAsCompletedFrames) {
  {
    std::ofstream old(work_.path() / (kPmsc + ".misses"), std::ios::binary);
    const char header[16] = {'\x89', 'M', 'I', 'S', '\r', '\n', '\x1a', '\n', 2, 0, 0, 0, 0, 0, 0, 0};
    old.write(header, sizeof header);
  }
  serve();
  auto stored = container::read_file(repository() / kPmsc / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  auto model = pmsc::load(*stored, kPmsc);
  ASSERT_TRUE(model.ok()) << model.error().message;
  auto arm = container::read_file(repository() / std::string(demo::kDemoModelName) / "1" / "model.anim");
  ASSERT_TRUE(arm.ok());
  auto frames = arm->float_matrix(container::sections::kSequenceFrames);
  ASSERT_TRUE(frames.ok());
  Eigen::VectorXf full = frames->row(3).transpose();
  for (long i = 0; i < full.size(); i += 3) full(i + 1) += 0.05f * static_cast<float>(i % 7);  // off the subspace
  const Eigen::VectorXf keys = pmsc::gather_key_values(*model, full);
  const auto K = static_cast<uint32_t>(model->key_point_count());

  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(kPmsc);
  request.set_local_fail_through(true);
  *request.add_poses()->mutable_key_values() = point_array({keys.data(), keys.data() + keys.size()}, K, 3);
  v1::EvaluateKeyPointsResponse evaluated;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(poses_->EvaluateKeyPoints(&context, request, &evaluated).ok());
  }
  const v1::PoseResult& result = evaluated.results(0);
  ASSERT_NE(result.status(), v1::CACHE_STATUS_HIT);
  ASSERT_GT(result.full_points_size(), 0);
  std::vector<float> values;
  for (uint32_t i : result.full_points()) values.insert(values.end(), &full(3 * i), &full(3 * i) + 3);
  v1::CompleteMissRequest complete;
  complete.mutable_model()->set_name(kPmsc);
  *complete.mutable_key_values() = request.poses(0).key_values();
  *complete.mutable_full_values() = point_array(values, static_cast<uint32_t>(result.full_points_size()), 3);
  *complete.mutable_full_points() = result.full_points();
  v1::CompleteMissResponse completed;
  {
    grpc::ClientContext context;
    const grpc::Status status = poses_->CompleteMiss(&context, complete, &completed);
    ASSERT_TRUE(status.ok()) << status.error_message();
  }
  EXPECT_TRUE(completed.logged());

  auto records = misslog::read_records(work_.path() / (kPmsc + ".misses"), 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  ASSERT_EQ(records->size(), 2u);  // the evaluation's miss (no full values), then the completion
  const misslog::MissRecord& logged = records->back();
  EXPECT_TRUE(logged.full_points.empty());
  ASSERT_EQ(logged.full_values.size(), static_cast<size_t>(full.size()));
  pmsc::PoseEstimate estimate;
  pmsc::evaluate(*model, keys, estimate);
  std::vector<float> expected(estimate.points.data(), estimate.points.data() + estimate.points.size());
  for (int k = 0; k < model->key_point_count(); ++k) {
    for (int c = 0; c < 3; ++c) expected[static_cast<size_t>(3 * model->key_points[static_cast<size_t>(k)] + c)] = keys(3 * k + c);
  }
  for (int j = 0; j < result.full_points_size(); ++j) {
    for (int c = 0; c < 3; ++c) expected[3 * result.full_points(j) + static_cast<uint32_t>(c)] = values[static_cast<size_t>(3 * j + c)];
  }
  EXPECT_EQ(logged.full_values, expected);
  std::ifstream log(work_.path() / (kPmsc + ".misses"), std::ios::binary);
  char header[12] = {};
  log.read(header, sizeof header);
  EXPECT_EQ(header[8], 2) << "the log keeps its version";
}

// Issue #54 item 9: a miss log that cannot be written (here a directory in its place) leaves the
// answer right and says so — logged false and the log's error — where a client said "completed 0".
TEST_F(PoseAndModelServiceTest, ACompletedMissThatCannotBeLoggedSaysWhy) {
  std::filesystem::create_directories(work_.path() / (kPmsc + ".misses"));
  serve();
  auto stored = container::read_file(repository() / kPmsc / "1" / "model.anim");
  ASSERT_TRUE(stored.ok());
  auto model = pmsc::load(*stored, kPmsc);
  ASSERT_TRUE(model.ok()) << model.error().message;
  Eigen::VectorXf full = model->mean;
  for (long i = 0; i < full.size(); i += 3) full(i + 1) += 0.05f * static_cast<float>(i % 7);  // off the subspace
  const Eigen::VectorXf key_values = pmsc::gather_key_values(*model, full);
  v1::CompleteMissRequest complete;
  complete.mutable_model()->set_name(kPmsc);
  *complete.mutable_key_values() = point_array({key_values.data(), key_values.data() + key_values.size()},
                                               static_cast<uint32_t>(model->key_point_count()), 3);
  *complete.mutable_full_values() = point_array({full.data(), full.data() + full.size()},
                                                static_cast<uint32_t>(full.size() / 3), 3);
  v1::CompleteMissResponse completed;
  grpc::ClientContext context;
  const grpc::Status status = poses_->CompleteMiss(&context, complete, &completed);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_NE(completed.result().status(), v1::CACHE_STATUS_HIT);
  EXPECT_FALSE(completed.logged());
  EXPECT_NE(completed.not_logged_reason().find((work_.path() / (kPmsc + ".misses")).string()), std::string::npos)
      << completed.not_logged_reason();
  EXPECT_EQ(completed.result().points().data().size(), static_cast<size_t>(full.size()) * sizeof(float))
      << "the answer itself is still sent";
}

// Issue #54 item 8: DescribeKeyPoints and every GetBasis chunk name the subspace by its SHA-256,
// which is the digest of the values exactly as the chunks carry them (computed here from the
// stream, not from the model).
TEST_F(PoseAndModelServiceTest, TheBasisIsNamedByTheSha256OfTheValuesSent) {
  serve();
  grpc::Status described;
  const v1::DescribeKeyPointsResponse keys = describe_keys(&described);
  ASSERT_TRUE(described.ok()) << described.error_message();
  ASSERT_EQ(keys.basis_sha256().size(), 32u);
  grpc::ClientContext context;
  v1::GetBasisRequest request;
  request.mutable_model()->set_name(kPmsc);
  auto reader = poses_->GetBasis(&context, request);
  std::string values;
  v1::BasisChunk chunk;
  while (reader->Read(&chunk)) {
    EXPECT_EQ(chunk.basis_sha256(), keys.basis_sha256());
    EXPECT_EQ(chunk.basis_checksum(), keys.basis_checksum());
    values += chunk.data();
  }
  ASSERT_TRUE(reader->Finish().ok());
  EXPECT_EQ(sha256(values), keys.basis_sha256());
}

}  // namespace
}  // namespace animspace
