// Check points through PoseService in process (issue #35): a client sends the check values beside
// the key values, the server measures e_check there and a HIT that the key points alone give
// becomes BLEND or MISS; bad check values are refused naming the field; a model without check
// points (a release-0.1 file) refuses them and keeps serving as before.
//
// The served model is the small repository's arm-pmsc with check points and thresholds set here,
// so that every verdict is decided by construction: the pose is the subspace estimate f̂ of a
// training frame, whose key values the projection reproduces (e_key at float rounding), and the
// check values are f̂ at the check points moved by a chosen distance δ along x (e_check = δ).
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/models.grpc.pb.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "core/pmsc/pmsc_io.h"
#include "harness/build_tree.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace fs = std::filesystem;
using testing::InProcessServer;
using testing::TempDir;
using Code = grpc::StatusCode;

const std::string kChecked = "checked-pmsc";
const std::string kOld = "release-pmsc";  // tests/fixtures/release-0.1/pmsc.anim: no check points
constexpr int kCheckPointCount = 4;
// ε of the checked model, model units (the arm is about 2 units long): far above the float
// rounding of f̂ (~1e-6), so that exact key values are a HIT and δ alone decides.
constexpr double kEpsilonMin = 0.01;
constexpr double kEpsilonMax = 0.02;

v1::PointArray point_array(const Eigen::VectorXf& values, uint32_t channels) {
  v1::PointArray a;
  a.set_point_count(static_cast<uint32_t>(values.size()) / channels);
  a.set_channel_count(channels);
  a.set_data(values.data(), static_cast<size_t>(values.size()) * sizeof(float));
  return a;
}

class CheckPointsTest : public testing::SmallRepositoryTest {
 protected:
  static void SetUpTestSuite() {
    SmallRepositoryTest::SetUpTestSuite();
    served_ = new TempDir();
    auto stored = container::read_file(repository() / std::string(demo::kDemoPmscModelName) / "1" / "model.anim");
    ASSERT_TRUE(stored.ok()) << stored.error().message;
    auto loaded = pmsc::load(*stored, kChecked);
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    model_ = new pmsc::PmscModel(std::move(*loaded));
    pmsc::PmscModel& m = *model_;
    // kCheckPointCount points spread over the arm, none a key point (whatever training chose).
    m.check_points.clear();
    m.check_regions.clear();
    std::vector<char> key(static_cast<size_t>(m.control_point_count), 0);
    for (int k : m.key_points) key[static_cast<size_t>(k)] = 1;
    for (int c = 0; c < kCheckPointCount; ++c) {
      int point = (2 * c + 1) * m.control_point_count / (2 * kCheckPointCount);
      while (key[static_cast<size_t>(point)]) ++point;
      m.check_points.push_back(point);
      if (m.region_count > 0) m.check_regions.push_back(m.point_regions[static_cast<size_t>(point)]);
    }
    m.key_weight = 1;
    m.epsilon = {kEpsilonMin, kEpsilonMax};
    m.key_only_epsilon = {kEpsilonMin, kEpsilonMax};
    ASSERT_TRUE(pmsc::prepare_projection(m).ok());
    pmsc::store(m, *stored);
    fs::create_directories(served_->path() / kChecked / "1");
    ASSERT_TRUE(container::write_file(served_->path() / kChecked / "1" / "model.anim", *stored).ok());
    fs::create_directories(served_->path() / kOld / "1");
    fs::copy_file(harness::source_dir() / "tests" / "fixtures" / "release-0.1" / "pmsc.anim", served_->path() / kOld / "1" / "model.anim");

    // The pose: f̂ of training frame 3 (sequence.frames holds the model's training frames).
    auto frames = stored->float_matrix(container::sections::kSequenceFrames);
    ASSERT_TRUE(frames.ok()) << frames.error().message;
    pmsc::PoseEstimate estimate;
    pmsc::evaluate(m, pmsc::gather_key_values(m, frames->row(3).transpose()), estimate);
    pose_ = new Eigen::VectorXf(estimate.points);
  }
  static void TearDownTestSuite() {
    delete pose_;
    delete model_;
    delete served_;
    pose_ = nullptr;
    model_ = nullptr;
    served_ = nullptr;
    SmallRepositoryTest::TearDownTestSuite();
  }

  void SetUp() override {
    server_ = std::make_unique<InProcessServer>(served_->path());
    poses_ = v1::PoseService::NewStub(server_->channel());
    models_ = v1::ModelService::NewStub(server_->channel());
  }

  static const pmsc::PmscModel& model() { return *model_; }
  static Eigen::VectorXf key_values() { return pmsc::gather_key_values(*model_, *pose_); }
  // f̂ at the check points, moved by δ along x: e_check = δ.
  static Eigen::VectorXf check_values(double delta) {
    Eigen::VectorXf checks = pmsc::gather_check_values(*model_, *pose_);
    for (long c = 0; c < checks.size(); c += 3) checks(c) += static_cast<float>(delta);
    return checks;
  }
  static v1::KeyPointPose pose(const Eigen::VectorXf* checks) {
    v1::KeyPointPose p;
    *p.mutable_key_values() = point_array(key_values(), 3);
    if (checks != nullptr) *p.mutable_check_values() = point_array(*checks, 3);
    return p;
  }

  grpc::Status evaluate(const std::string& name, const std::vector<v1::KeyPointPose>& poses,
                        v1::EvaluateKeyPointsResponse& response) {
    grpc::ClientContext context;
    v1::EvaluateKeyPointsRequest request;
    request.mutable_model()->set_name(name);
    for (const auto& p : poses) *request.add_poses() = p;
    return poses_->EvaluateKeyPoints(&context, request, &response);
  }

  static inline TempDir* served_ = nullptr;
  static inline pmsc::PmscModel* model_ = nullptr;
  static inline Eigen::VectorXf* pose_ = nullptr;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
  std::unique_ptr<v1::ModelService::Stub> models_;
};

TEST_F(CheckPointsTest, DescribeKeyPointsListsTheCheckPointsAModelWithoutThemNone) {
  for (const std::string& name : {kChecked, kOld}) {
    SCOPED_TRACE(name);
    grpc::ClientContext context;
    v1::DescribeKeyPointsRequest request;
    request.mutable_model()->set_name(name);
    v1::DescribeKeyPointsResponse keys;
    ASSERT_TRUE(poses_->DescribeKeyPoints(&context, request, &keys).ok());
    EXPECT_GT(keys.key_point_indices_size(), 0);
    const std::vector<uint32_t> indices(keys.check_point_indices().begin(), keys.check_point_indices().end());
    const std::vector<uint32_t> regions(keys.check_point_regions().begin(), keys.check_point_regions().end());
    if (name == kOld) {
      EXPECT_TRUE(indices.empty());
      EXPECT_TRUE(regions.empty());
      continue;
    }
    EXPECT_EQ(indices, std::vector<uint32_t>(model().check_points.begin(), model().check_points.end()));
    EXPECT_EQ(regions, std::vector<uint32_t>(model().check_regions.begin(), model().check_regions.end()));
  }
}

TEST_F(CheckPointsTest, CheckValuesOverturnTheHitOfExactKeyValues) {
  const Eigen::VectorXf exact = check_values(0), blend = check_values(0.015), miss = check_values(0.5);
  // One batch, so that each pose's check values must travel with it through the batcher.
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(evaluate(kChecked, {pose(nullptr), pose(&blend), pose(&exact), pose(&miss)}, response).ok());
  ASSERT_EQ(response.results_size(), 4);

  const v1::PoseResult& unchecked = response.results(0);
  EXPECT_EQ(unchecked.status(), v1::CACHE_STATUS_HIT);
  EXPECT_FALSE(unchecked.checked());
  EXPECT_EQ(unchecked.check_point_error(), 0.0f);
  // Without check values the estimate is the key term: the worst key's residual (issue #52).
  EXPECT_EQ(unchecked.error_estimate(), unchecked.key_point_max_error());
  EXPECT_GE(unchecked.key_point_max_error(), unchecked.key_point_error());
  EXPECT_LT(unchecked.key_point_error(), 1e-4);

  // e = max(e_key, e_check) = δ = 0.015: α = (0.015 − 0.01) / (0.02 − 0.01) = 0.5.
  const v1::PoseResult& blended = response.results(1);
  EXPECT_EQ(blended.status(), v1::CACHE_STATUS_BLEND);
  EXPECT_TRUE(blended.checked());
  EXPECT_NEAR(blended.check_point_error(), 0.015, 1e-4);
  EXPECT_NEAR(blended.error_estimate(), 0.015, 1e-4);
  EXPECT_NEAR(blended.blend_weight(), 0.5, 1e-2);
  EXPECT_EQ(blended.key_point_error(), unchecked.key_point_error()) << "check values never reach the projection";
  EXPECT_TRUE(blended.full_evaluation_needed());

  const v1::PoseResult& confirmed = response.results(2);
  EXPECT_EQ(confirmed.status(), v1::CACHE_STATUS_HIT);
  EXPECT_TRUE(confirmed.checked());
  EXPECT_LT(confirmed.check_point_error(), 1e-4);

  const v1::PoseResult& missed = response.results(3);
  EXPECT_EQ(missed.status(), v1::CACHE_STATUS_MISS);
  EXPECT_NEAR(missed.check_point_error(), 0.5, 1e-4);
  EXPECT_EQ(missed.blend_weight(), 1.0f);

  // The points do not depend on the check values: f̂ for all four (no full values yet), up to the
  // rounding of one column of the batch's product against another.
  const auto floats = [](const v1::PoseResult& r) {
    return Eigen::Map<const Eigen::VectorXf>(reinterpret_cast<const float*>(r.points().data().data()),
                                             static_cast<long>(r.points().data().size() / sizeof(float)));
  };
  ASSERT_EQ(floats(unchecked).size(), pose_->size());
  EXPECT_LT((floats(blended) - floats(unchecked)).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LT((floats(missed) - floats(unchecked)).cwiseAbs().maxCoeff(), 1e-5);
}

TEST_F(CheckPointsTest, TheStreamAndTheLocalPathJudgeWithTheCheckValuesToo) {
  const Eigen::VectorXf blend = check_values(0.015);
  {
    grpc::ClientContext context;
    auto stream = poses_->StreamKeyPoints(&context);
    v1::KeyPointFrame frame;
    frame.mutable_model()->set_name(kChecked);
    *frame.mutable_pose() = pose(&blend);
    frame.set_sequence(7);
    ASSERT_TRUE(stream->Write(frame));
    frame.clear_model();
    *frame.mutable_pose() = pose(nullptr);
    frame.set_sequence(8);
    ASSERT_TRUE(stream->Write(frame));
    stream->WritesDone();
    v1::PoseResult result;
    ASSERT_TRUE(stream->Read(&result));
    EXPECT_EQ(result.sequence(), 7u);
    EXPECT_EQ(result.status(), v1::CACHE_STATUS_BLEND);
    EXPECT_NEAR(result.check_point_error(), 0.015, 1e-4);
    ASSERT_TRUE(stream->Read(&result));
    EXPECT_EQ(result.sequence(), 8u);
    EXPECT_EQ(result.status(), v1::CACHE_STATUS_HIT);
    EXPECT_FALSE(result.checked());
    EXPECT_TRUE(stream->Finish().ok());
  }
  // Local fail-through does not take the batched path.
  grpc::ClientContext context;
  v1::EvaluateKeyPointsRequest request;
  request.mutable_model()->set_name(kChecked);
  request.set_local_fail_through(true);
  *request.add_poses() = pose(&blend);
  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(poses_->EvaluateKeyPoints(&context, request, &response).ok());
  EXPECT_EQ(response.results(0).status(), v1::CACHE_STATUS_BLEND);
  EXPECT_TRUE(response.results(0).checked());
  EXPECT_NEAR(response.results(0).error_estimate(), 0.015, 1e-4);
}

TEST_F(CheckPointsTest, CompleteMissWithTheSameCheckValuesRepeatsTheVerdict) {
  const Eigen::VectorXf blend = check_values(0.015);
  // Full values that repeat the key values: f̂ itself, the check points as sent.
  Eigen::VectorXf full = *pose_;
  for (int c = 0; c < kCheckPointCount; ++c) {
    full.segment(3 * model().check_points[static_cast<size_t>(c)], 3) = blend.segment(3 * c, 3);
  }
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name(kChecked);
  *request.mutable_key_values() = point_array(key_values(), 3);
  *request.mutable_check_values() = point_array(blend, 3);
  *request.mutable_full_values() = point_array(full, 3);
  v1::CompleteMissResponse completed;
  {
    grpc::ClientContext context;
    const grpc::Status status = poses_->CompleteMiss(&context, request, &completed);
    ASSERT_TRUE(status.ok()) << status.error_message();
  }
  EXPECT_EQ(completed.result().status(), v1::CACHE_STATUS_BLEND);
  EXPECT_NEAR(completed.result().blend_weight(), 0.5, 1e-2);
  EXPECT_FALSE(completed.result().full_evaluation_needed());
  EXPECT_TRUE(completed.logged());
  // Without them the same completion is the key-only verdict: a HIT, nothing to blend or log.
  request.clear_check_values();
  grpc::ClientContext context;
  ASSERT_TRUE(poses_->CompleteMiss(&context, request, &completed).ok());
  EXPECT_EQ(completed.result().status(), v1::CACHE_STATUS_HIT);
  EXPECT_FALSE(completed.logged());
}

// Full values must be the pose its check values were read from, as they must repeat its key
// values: a wrong "full pose" would teach the next retrain a wrong example.
TEST_F(CheckPointsTest, CompleteMissRefusesFullValuesThatDoNotRepeatTheCheckValues) {
  const Eigen::VectorXf blend = check_values(0.015);
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name(kChecked);
  *request.mutable_key_values() = point_array(key_values(), 3);
  *request.mutable_check_values() = point_array(blend, 3);
  *request.mutable_full_values() = point_array(*pose_, 3);  // f̂: 0.015 off every check point
  v1::CompleteMissResponse completed;
  grpc::ClientContext context;
  const grpc::Status status = poses_->CompleteMiss(&context, request, &completed);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  const std::string expected = "full_values: check point 0 (point " + std::to_string(model().check_points[0]) + ")";
  EXPECT_NE(status.error_message().find(expected), std::string::npos) << status.error_message();
  // Partial full values are checked at the check points they hold.
  const int point = model().check_points[0];
  request.add_full_points(static_cast<uint32_t>(point));
  *request.mutable_full_values() = point_array(pose_->segment(3 * point, 3), 3);
  grpc::ClientContext partial_context;
  const grpc::Status partial = poses_->CompleteMiss(&partial_context, request, &completed);
  EXPECT_EQ(partial.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(partial.error_message().find("check point 0"), std::string::npos) << partial.error_message();
}

TEST_F(CheckPointsTest, BadCheckValuesAreRefusedNamingTheField) {
  const std::string C = std::to_string(kCheckPointCount);
  const Eigen::VectorXf good = check_values(0);
  const Eigen::VectorXf short_checks = good.head(good.size() - 3);
  Eigen::VectorXf nan_checks = good;
  nan_checks(4) = std::numeric_limits<float>::quiet_NaN();
  struct Case {
    const char* name;
    Eigen::VectorXf checks;
    uint32_t channels;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"one point short", short_checks, 3,
       "poses[1].check_values.point_count: expected " + C + " check points, got " + std::to_string(kCheckPointCount - 1)},
      {"NaN", nan_checks, 3, "poses[1].check_values.data: value of point 1, channel 1 is NaN"},
      {"two channels", good, 2, "poses[1].check_values.point_count: expected " + C + " check points, got " +
                                    std::to_string(kCheckPointCount * 3 / 2)},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    v1::KeyPointPose bad = pose(nullptr);
    *bad.mutable_check_values() = point_array(c.checks, c.channels);
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = evaluate(kChecked, {pose(&good), bad}, response);
    EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find(c.message), std::string::npos) << status.error_message();
  }
  // A stream names the frame; CompleteMiss its own field.
  {
    grpc::ClientContext context;
    auto stream = poses_->StreamKeyPoints(&context);
    v1::KeyPointFrame frame;
    frame.mutable_model()->set_name(kChecked);
    *frame.mutable_pose() = pose(&short_checks);
    frame.set_sequence(42);
    ASSERT_TRUE(stream->Write(frame));
    stream->WritesDone();
    v1::PoseResult result;
    EXPECT_FALSE(stream->Read(&result));
    const grpc::Status status = stream->Finish();
    EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("42"), std::string::npos) << status.error_message();
    EXPECT_NE(status.error_message().find("check_values.point_count: expected " + C + " check points"),
              std::string::npos)
        << status.error_message();
  }
  v1::CompleteMissRequest complete;
  complete.mutable_model()->set_name(kChecked);
  *complete.mutable_key_values() = point_array(key_values(), 3);
  *complete.mutable_check_values() = point_array(short_checks, 3);
  *complete.mutable_full_values() = point_array(*pose_, 3);
  v1::CompleteMissResponse completed;
  grpc::ClientContext context;
  const grpc::Status status = poses_->CompleteMiss(&context, complete, &completed);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("check_values.point_count: expected " + C + " check points, got " +
                                        std::to_string(kCheckPointCount - 1)),
            std::string::npos)
      << status.error_message();
  // Nothing of a refused batch is counted.
  const auto stats = server_->environment().metrics.model_statistics();
  const auto it = stats.find(kChecked);
  EXPECT_TRUE(it == stats.end() || it->second.poses == 0);
}

TEST_F(CheckPointsTest, AModelWithoutCheckPointsRefusesCheckValuesAndServesAsBefore) {
  grpc::ClientContext describe_context;
  v1::DescribeKeyPointsRequest describe;
  describe.mutable_model()->set_name(kOld);
  v1::DescribeKeyPointsResponse keys;
  ASSERT_TRUE(poses_->DescribeKeyPoints(&describe_context, describe, &keys).ok());
  const auto K = static_cast<uint32_t>(keys.key_point_indices_size());
  v1::KeyPointPose old_pose;
  *old_pose.mutable_key_values() = point_array(Eigen::VectorXf::Zero(K * keys.channel_count()), keys.channel_count());

  v1::EvaluateKeyPointsResponse response;
  ASSERT_TRUE(evaluate(kOld, {old_pose}, response).ok());
  EXPECT_FALSE(response.results(0).checked());
  // A model trained before issue #52 keeps e_key as its key term.
  EXPECT_EQ(response.results(0).error_estimate(), response.results(0).key_point_error());
  // An empty array is no check values (a client that always fills the field from an empty list).
  v1::KeyPointPose empty = old_pose;
  empty.mutable_check_values()->set_channel_count(keys.channel_count());
  ASSERT_TRUE(evaluate(kOld, {empty}, response).ok());
  EXPECT_FALSE(response.results(0).checked());

  v1::KeyPointPose sent = old_pose;
  *sent.mutable_check_values() = point_array(Eigen::VectorXf::Zero(keys.channel_count()), keys.channel_count());
  const grpc::Status status = evaluate(kOld, {sent}, response);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("poses[0].check_values: model '" + kOld + "' version 1 has no check points"),
            std::string::npos)
      << status.error_message();
}

TEST_F(CheckPointsTest, ModelVersionCarriesTheCheckPointsAndTheCalibrationStatement) {
  for (const std::string& name : {kChecked, kOld}) {
    SCOPED_TRACE(name);
    grpc::ClientContext context;
    v1::DescribeModelRequest request;
    request.mutable_model()->set_name(name);
    v1::DescribeModelResponse response;
    ASSERT_TRUE(models_->DescribeModel(&context, request, &response).ok());
    ASSERT_EQ(response.model().versions_size(), 1);
    const v1::ModelVersion& v = response.model().versions(0);
    auto file = container::read_file(served_->path() / name / "1" / "model.anim");
    ASSERT_TRUE(file.ok());
    auto loaded = pmsc::load(*file, name);
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    EXPECT_EQ(v.check_point_count(), name == kChecked ? static_cast<uint32_t>(kCheckPointCount) : 0u);
    EXPECT_EQ(v.false_hit_rate(), loaded->calibration.false_hit_rate);
    EXPECT_EQ(v.calibration_bad_samples(), static_cast<uint64_t>(loaded->calibration.bad_samples));
    EXPECT_EQ(v.calibration_real_bad_samples(), static_cast<uint64_t>(std::min(loaded->calibration.over_tolerance,
                                                                               loaded->calibration.bad_samples)));
    EXPECT_EQ(v.calibration_guarantee_holds(), pmsc::calibration_guarantee_holds(*loaded));
    EXPECT_FALSE(v.calibration_statement().empty());
    EXPECT_EQ(v.calibration_statement(), pmsc::calibration_statement(*loaded));
  }
  // A release-0.1 model was calibrated before anything could be guaranteed.
  grpc::ClientContext context;
  v1::DescribeModelRequest request;
  request.mutable_model()->set_name(kOld);
  v1::DescribeModelResponse response;
  ASSERT_TRUE(models_->DescribeModel(&context, request, &response).ok());
  EXPECT_FALSE(response.model().versions(0).calibration_guarantee_holds());
  EXPECT_EQ(response.model().versions(0).calibration_statement().rfind("no guarantee", 0), 0u);
}

}  // namespace
}  // namespace animspace
