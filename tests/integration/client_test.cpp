// animspace::Client (clients/cpp) against the real animspaced serving the demo repository. The
// answers are checked against the core library evaluating the same model files in-process — an
// independent path that never touches the client or the wire — and the stream session against
// unary evaluation of the same frames.
#include <atomic>
#include <chrono>
#include <cmath>
#include <span>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/misslog/miss_log.h"
#include "core/container/sections.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/pmsc_model.h"
#include "core/pmsc/soft_cache.h"
#include "animspace/v1/poses.grpc.pb.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/metrics_scrape.h"
#include "tests/support/pmsc_fixtures.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

namespace as = animation_space;
using harness::DaemonProcess;
using testing::TempDir;

const std::string kPmsc(demo::kDemoPmscModelName);
const std::string kAnimationSpace(demo::kDemoAnimationSpaceModelName);

class ClientTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    repo_ = new TempDir();
    work_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(repo_->path()).ok());
    daemon_ = new DaemonProcess({"--model-repository", repo_->path().string(), "--miss-log-dir",
                                 work_->path().string(), "--renderer", "none"},
                                work_->path());
    client_ = new Client(daemon_->address());
    ASSERT_TRUE(testing::wait_until_serving(*client_));

    // The expensive rig's frames (demo `arm`) and the PMSC model trained on them, read here.
    auto arm = container::read_file(repo_->path() / "arm" / "1" / "model.anim");
    ASSERT_TRUE(arm.ok());
    auto frames = arm->float_matrix(container::sections::kSequenceFrames);
    ASSERT_TRUE(frames.ok());
    frames_ = new FrameMatrix(std::move(*frames));
    auto pmsc_file = container::read_file(repo_->path() / kPmsc / "1" / "model.anim");
    ASSERT_TRUE(pmsc_file.ok());
    auto pmsc = pmsc::load(*pmsc_file, kPmsc);
    ASSERT_TRUE(pmsc.ok()) << pmsc.error().message;
    pmsc_ = new pmsc::PmscModel(std::move(*pmsc));
    ASSERT_TRUE(pmsc::prepare_projection(*pmsc_).ok());
  }
  static void TearDownTestSuite() {
    delete pmsc_;
    delete frames_;
    delete client_;
    delete daemon_;
    delete work_;
    delete repo_;
  }

  static std::span<const float> frame(int f) {
    return {frames_->row(f).data(), static_cast<size_t>(frames_->cols())};
  }

  // Frame f with its points pushed along y: far from anything trained, so the cache blends or
  // misses it.
  static std::vector<float> perturbed_frame(int f) {
    std::vector<float> full(frame(f).begin(), frame(f).end());
    for (size_t i = 0; i < full.size(); i += 3) full[i + 1] += 0.05f * static_cast<float>(i % 7);
    return full;
  }

  // Records in the miss log of kPmsc that this suite's daemon writes (0 before its first miss).
  static size_t logged_records() {
    auto records = misslog::read_records(work_->path() / (kPmsc + ".misses"), 0, nullptr);
    return records.ok() ? records->size() : size_t{0};
  }

  // What the soft cache makes of frame f, computed in-process from the model file.
  static pmsc::PoseEstimate expected_estimate(int f) {
    pmsc::PoseEstimate estimate;
    pmsc::evaluate(*pmsc_, pmsc::gather_key_values(*pmsc_, frames_->row(f).transpose()), estimate);
    return estimate;
  }

  static void expect_matches_core(const PoseResult& result, int f) {
    const pmsc::PoseEstimate expected = expected_estimate(f);
    ASSERT_EQ(result.points.channel_count, 3u);
    ASSERT_EQ(result.points.values.size(), static_cast<size_t>(expected.points.size()));
    const float scale = frames_->row(f).cwiseAbs().maxCoeff();
    for (Eigen::Index i = 0; i < expected.points.size(); ++i) {
      ASSERT_NEAR(result.points.values[static_cast<size_t>(i)], expected.points(i), 1e-5f * scale)
          << "frame " << f << ", value " << i;
    }
    EXPECT_NEAR(result.key_point_error, expected.key_point_error, 1e-5 * scale + 1e-4 * expected.key_point_error);
    const pmsc::SoftCacheDecision decision = pmsc::decide(result.key_point_error, pmsc_->epsilon);
    const v1::CacheStatus expected_status = decision.status == pmsc::CacheStatus::kHit     ? v1::CACHE_STATUS_HIT
                                            : decision.status == pmsc::CacheStatus::kBlend ? v1::CACHE_STATUS_BLEND
                                                                                            : v1::CACHE_STATUS_MISS;
    EXPECT_EQ(result.status, expected_status) << "frame " << f;
    EXPECT_NEAR(result.blend_weight, decision.alpha, 1e-6);
  }

  static TempDir* repo_;
  static TempDir* work_;
  static DaemonProcess* daemon_;
  static Client* client_;
  static FrameMatrix* frames_;
  static pmsc::PmscModel* pmsc_;
};

TempDir* ClientTest::repo_ = nullptr;
TempDir* ClientTest::work_ = nullptr;
DaemonProcess* ClientTest::daemon_ = nullptr;
Client* ClientTest::client_ = nullptr;
FrameMatrix* ClientTest::frames_ = nullptr;
pmsc::PmscModel* ClientTest::pmsc_ = nullptr;

TEST_F(ClientTest, DescribeKeyPointsGivesTheModelsKeysAndGathersThem) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  ASSERT_EQ(keys.indices.size(), pmsc_->key_points.size());
  for (size_t k = 0; k < keys.indices.size(); ++k) EXPECT_EQ(keys.indices[k], static_cast<uint32_t>(pmsc_->key_points[k]));
  EXPECT_EQ(keys.channel_count, 3u);
  EXPECT_EQ(keys.control_point_count, static_cast<uint32_t>(pmsc_->control_point_count));
  EXPECT_EQ(keys.fail_through, v1::FAIL_THROUGH_CLIENT);
  const std::vector<float> gathered = keys.gather(frame(5));
  const Eigen::VectorXf expected = pmsc::gather_key_values(*pmsc_, frames_->row(5).transpose());
  ASSERT_EQ(gathered.size(), static_cast<size_t>(expected.size()));
  for (size_t i = 0; i < gathered.size(); ++i) EXPECT_EQ(gathered[i], expected(static_cast<Eigen::Index>(i)));
  EXPECT_THROW(keys.gather(frame(5).first(9)), std::invalid_argument);
}

TEST_F(ClientTest, UnaryAndBatchEvaluationMatchTheCoreInProcess) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  // Odd frames were held out of training, so some may blend or miss.
  std::vector<std::vector<float>> values;
  for (int f = 1; f < 40; f += 3) values.push_back(keys.gather(frame(f)));
  std::vector<KeyPointPose> poses;
  for (const auto& v : values) poses.push_back({v, keys.channel_count});
  const std::vector<PoseResult> batch = client_->evaluate_key_points_batch(kPmsc, poses);
  ASSERT_EQ(batch.size(), poses.size());
  for (size_t i = 0; i < batch.size(); ++i) {
    expect_matches_core(batch[i], 1 + 3 * static_cast<int>(i));
    EXPECT_EQ(batch[i].model_version, keys.model_version);
    // A batch answers each pose as a single call does, up to the order of the reconstruction's
    // float additions (the batch is one matrix product, server/pose_batcher.h).
    const PoseResult single = client_->evaluate_key_points(kPmsc, poses[i]);
    EXPECT_EQ(single.status, batch[i].status);
    EXPECT_EQ(single.key_point_error, batch[i].key_point_error);
    ASSERT_EQ(single.points.values.size(), batch[i].points.values.size());
    const Eigen::VectorXd tolerance =
        testing::reconstruction_tolerance(*pmsc_, expected_estimate(1 + 3 * static_cast<int>(i)).coordinates);
    for (size_t v = 0; v < single.points.values.size(); ++v) {
      ASSERT_LE(std::abs(single.points.values[v] - batch[i].points.values[v]), tolerance(static_cast<long>(v)))
          << "pose " << i << ", value " << v;
    }
  }
  EvaluateOptions verdicts_only;
  verdicts_only.omit_points = true;
  const PoseResult probe = client_->evaluate_key_points(kPmsc, poses[0], verdicts_only);
  EXPECT_TRUE(probe.points.empty());
  EXPECT_EQ(probe.status, batch[0].status);
}

TEST_F(ClientTest, TheStreamSessionAnswersInOrderWithinItsWindow) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  const int count = 90;
  StreamOptions options;
  options.window = 3;
  auto stream = client_->open_stream(kPmsc, options);
  size_t worst_in_flight = 0;
  std::atomic<bool> written{false};
  std::thread writer([&] {
    for (int f = 0; f < count; ++f) {
      const std::vector<float> v = keys.gather(frame(f));
      // Sequence numbers need not be contiguous: the client's own frame numbers come back.
      EXPECT_TRUE(stream->write({v, keys.channel_count}, 1000 + 7 * static_cast<uint64_t>(f)));
      worst_in_flight = std::max(worst_in_flight, stream->in_flight());
    }
    stream->writes_done();
    written.store(true);
  });
  std::vector<PoseResult> results;
  for (;;) {
    // The reader lags on purpose: before each read it lets the writer fill the window, so the
    // writer meets a full window on every frame — without back-pressure it would run ahead by
    // the whole sequence.
    EXPECT_TRUE(testing::wait_until([&] { return stream->in_flight() >= options.window || written.load(); },
                                    std::chrono::seconds(30), std::chrono::milliseconds(1)));
    auto result = stream->read();
    if (!result) break;
    results.push_back(std::move(*result));
  }
  writer.join();
  stream->finish();
  ASSERT_EQ(results.size(), static_cast<size_t>(count));
  // The reader let the window fill before every read: the writer met it full and went no further.
  EXPECT_EQ(worst_in_flight, 3u) << "the writer ran past the window, or never reached it";
  for (int f = 0; f < count; ++f) {
    EXPECT_EQ(results[static_cast<size_t>(f)].sequence, 1000 + 7 * static_cast<uint64_t>(f));
    expect_matches_core(results[static_cast<size_t>(f)], f);
  }
}

TEST_F(ClientTest, OneThreadCanAlternateWritesAndReads) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  StreamOptions options;
  options.window = 2;
  options.omit_points = true;
  auto stream = client_->open_stream(kPmsc, options);
  std::vector<uint64_t> answered;
  for (uint64_t f = 0; f < 20; ++f) {
    if (stream->in_flight() == stream->window()) answered.push_back(stream->read()->sequence);
    const std::vector<float> v = keys.gather(frame(static_cast<int>(f)));
    ASSERT_TRUE(stream->write({v, keys.channel_count}, f));
  }
  stream->writes_done();
  while (auto result = stream->read()) {
    EXPECT_TRUE(result->points.empty());
    answered.push_back(result->sequence);
  }
  stream->finish();
  ASSERT_EQ(answered.size(), 20u);
  for (uint64_t f = 0; f < 20; ++f) EXPECT_EQ(answered[f], f);
}

TEST_F(ClientTest, ABadFrameEndsTheStreamWithTheServersStatusAfterTheGoodOnes) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  auto stream = client_->open_stream(kPmsc);
  std::vector<float> good = keys.gather(frame(2));
  std::vector<float> short_frame(good.begin(), good.end() - 3);  // one key point too few
  ASSERT_TRUE(stream->write({good, 3}, 1));
  ASSERT_TRUE(stream->write({good, 3}, 2));
  stream->write({short_frame, 3}, 3);  // may already see the broken stream: false is fine
  stream->writes_done();
  int read = 0;
  while (auto result = stream->read()) ++read;
  EXPECT_EQ(read, 2);
  try {
    stream->finish();
    FAIL() << "a frame with a key point missing was accepted";
  } catch (const RpcError& error) {
    EXPECT_EQ(error.code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(error.server_message().find("frame[sequence=3]"), std::string::npos) << error.server_message();
    EXPECT_NE(error.server_message().find("expected " + std::to_string(keys.indices.size()) + " key points"),
              std::string::npos)
        << error.server_message();
  }
}

TEST_F(ClientTest, AnAbandonedStreamIsCancelledAndTheServerCarriesOn) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  {
    auto stream = client_->open_stream(kPmsc);
    const std::vector<float> v = keys.gather(frame(0));
    ASSERT_TRUE(stream->write({v, 3}, 0));
    ASSERT_TRUE(stream->read().has_value());
    EXPECT_THROW(stream->finish(), std::logic_error) << "finish() before the end would hang gRPC";
  }  // destroyed unfinished: cancelled
  EXPECT_EQ(client_->health(), grpc::health::v1::HealthCheckResponse::SERVING);
  const std::vector<float> v = keys.gather(frame(0));
  EXPECT_EQ(client_->evaluate_key_points(kPmsc, {v, 3}).points.point_count, keys.control_point_count);
}

TEST_F(ClientTest, CompleteMissBlendsTheCallersFullValuesByAlpha) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  const std::vector<float> full = perturbed_frame(3);
  const std::vector<float> v = keys.gather(full);
  const PoseResult evaluated = client_->evaluate_key_points(kPmsc, {v, 3});
  ASSERT_NE(evaluated.status, v1::CACHE_STATUS_HIT) << "the perturbed pose should not be a hit";
  EXPECT_TRUE(evaluated.full_evaluation_needed);
  const CompletedMiss completed = client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, full);
  EXPECT_TRUE(completed.logged);
  const float alpha = evaluated.blend_weight;
  ASSERT_EQ(completed.result.points.values.size(), full.size());
  for (size_t i = 0; i < full.size(); ++i) {
    const float expected = alpha * full[i] + (1 - alpha) * evaluated.points.values[i];
    ASSERT_NEAR(completed.result.points.values[i], expected, 1e-5f) << "value " << i;
  }
  EXPECT_THROW(client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, std::span(full).first(10)),
               std::invalid_argument);
}

// Issue #55 item 6: a miss log at its bound (--miss-log-max-bytes) takes no more records; the pose
// is still answered, the completion says why it was not logged, and the metric counts it.
TEST_F(ClientTest, AFullMissLogServesThePoseAndSaysWhyItWasNotLogged) {
  TempDir work;
  const int metrics_port = testing::free_tcp_port();
  // 17 bytes: the 16-byte file header and no room for any record.
  DaemonProcess daemon({"--model-repository", repo_->path().string(), "--miss-log-dir", work.path().string(),
                        "--renderer", "none", "--miss-log-max-bytes", "17", "--metrics-listen",
                        "127.0.0.1:" + std::to_string(metrics_port)},
                       work.path());
  Client client(daemon.address());
  ASSERT_TRUE(testing::wait_until_serving(client));
  const KeyPoints keys = client.describe_key_points(kPmsc);
  const std::vector<float> full = perturbed_frame(5);
  const std::vector<float> v = keys.gather(full);
  const PoseResult evaluated = client.evaluate_key_points(kPmsc, {v, 3});
  ASSERT_NE(evaluated.status, v1::CACHE_STATUS_HIT) << "the perturbed pose should not be a hit";
  const CompletedMiss completed = client.complete_miss(kPmsc, evaluated.model_version, {v, 3}, full);
  EXPECT_FALSE(completed.logged);
  EXPECT_NE(completed.not_logged_reason.find("the miss log is full"), std::string::npos) << completed.not_logged_reason;
  EXPECT_NE(completed.not_logged_reason.find("--miss-log-max-bytes"), std::string::npos) << completed.not_logged_reason;
  EXPECT_EQ(completed.result.points.values.size(), full.size()) << "the answer is served all the same";
  auto records = misslog::read_records(work.path() / (kPmsc + ".misses"), 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  EXPECT_TRUE(records->empty());
  const auto page = testing::scrape_metrics(metrics_port);
  ASSERT_TRUE(page.has_value());
  EXPECT_EQ(testing::metric_value(*page, "animspace_misses_not_logged_total{model=\"" + kPmsc + "\",reason=\"full\"}"),
            2.0)
      << *page;
}

// Issue #55 item 6: a completion sent as test traffic is answered — the same blend — but not logged,
// and says why.
TEST_F(ClientTest, ACompletionSentAsTestTrafficIsAnsweredButNotLogged) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  const std::vector<float> full = perturbed_frame(7);
  const std::vector<float> v = keys.gather(full);
  const PoseResult evaluated = client_->evaluate_key_points(kPmsc, {v, 3}, {.skip_miss_log = true});
  ASSERT_NE(evaluated.status, v1::CACHE_STATUS_HIT) << "the perturbed pose should not be a hit";
  const size_t before = logged_records();
  const CompletedMiss skipped =
      client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, full, {}, v1::POINT_ENCODING_UNSPECIFIED, true);
  EXPECT_FALSE(skipped.logged);
  EXPECT_NE(skipped.not_logged_reason.find("skip_miss_log"), std::string::npos) << skipped.not_logged_reason;
  EXPECT_EQ(logged_records(), before) << "test traffic reached the miss log";
  const CompletedMiss logged = client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, full);
  EXPECT_TRUE(logged.logged);
  EXPECT_EQ(logged_records(), before + 1);
  EXPECT_EQ(skipped.result.points.values, logged.result.points.values) << "the same blend either way";
}

// Issue #21: the tour sent an all-zero "full pose" and the server logged it as tomorrow's
// training example. Full values must repeat the key values at the key points.
TEST_F(ClientTest, CompleteMissRefusesFullValuesThatAreNotTheKeyPoseAndNeverLogsThem) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  const std::vector<float> full = perturbed_frame(5);
  const std::vector<float> v = keys.gather(full);
  const PoseResult evaluated = client_->evaluate_key_points(kPmsc, {v, 3});
  ASSERT_NE(evaluated.status, v1::CACHE_STATUS_HIT) << "the perturbed pose should not be a hit";
  const size_t before = logged_records();

  auto refusal = [&](const std::vector<float>& wrong) {
    try {
      client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, wrong);
    } catch (const RpcError& e) {
      EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT) << e.what();
      return e.server_message();
    }
    ADD_FAILURE() << "an inconsistent full pose was accepted";
    return std::string();
  };
  // All zeros: the first key point already differs.
  const std::string zeros = refusal(std::vector<float>(full.size(), 0.0f));
  const std::string point0 = std::to_string(keys.indices[0]);
  EXPECT_NE(zeros.find("full_values: key point 0 (point " + point0 + "): the full values hold (0, 0, 0)"),
            std::string::npos)
      << zeros;
  // One channel of the fourth key point off by 1e-3 (the model is about 3 units long).
  std::vector<float> moved = full;
  moved[3 * keys.indices[3] + 2] += 1e-3f;
  const std::string one = refusal(moved);
  EXPECT_NE(one.find("full_values: key point 3 (point " + std::to_string(keys.indices[3]) + ")"), std::string::npos)
      << one;
  EXPECT_EQ(logged_records(), before) << "a refused completion must not reach the miss log";

  // Rounding is not a mismatch: every key value one float step away is accepted, and logged.
  std::vector<float> rounded = full;
  for (uint32_t index : keys.indices) {
    for (int c = 0; c < 3; ++c) {
      float& value = rounded[3 * index + c];
      value = std::nextafter(value, value + 1.0f);
    }
  }
  EXPECT_TRUE(client_->complete_miss(kPmsc, evaluated.model_version, {v, 3}, rounded).logged);
  EXPECT_EQ(logged_records(), before + 1);
}

// Local fail-through (issue #22): one region of frame f moved, so that only the regions whose
// key points see it fail. The client computes and sends only the points the server names.
TEST_F(ClientTest, LocalFailThroughNamesTheFailingPointsAndCompletesThemAlone) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  ASSERT_GT(pmsc_->region_count, 1);
  const int moved_region = pmsc_->key_regions[0];
  std::vector<float> full(frame(7).begin(), frame(7).end());
  for (size_t i = 0; i < full.size() / 3; ++i) {
    if (pmsc_->point_regions[i] == moved_region) full[3 * i + 1] += 0.1f;
  }
  // Sent with its check values: regions are calibrated for estimates that include them (a pose
  // without them takes the whole-pose α everywhere, local_fail_through.h).
  const std::vector<float> v = keys.gather(full), checks = keys.gather_check_values(full);
  const KeyPointPose pose{.key_values = v, .channel_count = 3, .check_values = checks};
  EvaluateOptions options;
  options.local_fail_through = true;
  const PoseResult evaluated = client_->evaluate_key_points(kPmsc, pose, options);
  ASSERT_NE(evaluated.status, v1::CACHE_STATUS_HIT) << "e_key " << evaluated.key_point_error;
  ASSERT_GE(evaluated.full_points.size(), 2u);
  const size_t N = full.size() / 3;
  EXPECT_LT(evaluated.full_points.size(), N) << "every region failed: the test pose is not local";

  // The points and weights, independently: each region's verdict (eqs. 9–11 on its own key
  // points' RMS error and thresholds), weighted by the stored memberships.
  pmsc::PoseEstimate estimate;
  pmsc::estimate_coordinates(*pmsc_, Eigen::Map<const Eigen::VectorXf>(v.data(), static_cast<long>(v.size())),
                             Eigen::Map<const Eigen::VectorXf>(checks.data(), static_cast<long>(checks.size())),
                             estimate);
  std::vector<uint32_t> expected_points;
  std::vector<double> expected_alpha;
  for (size_t i = 0; i < N; ++i) {
    double alpha = 0;
    for (int r = 0; r < pmsc_->region_count; ++r) {
      const double w = pmsc_->region_weights.size() > 0 ? pmsc_->region_weights(static_cast<long>(i), r)
                                                          : (pmsc_->point_regions[i] == r ? 1.0 : 0.0);
      alpha += w * pmsc::decide(estimate.region_errors[static_cast<size_t>(r)], pmsc::region_thresholds(*pmsc_, r)).alpha;
    }
    if (alpha > 0) {
      expected_points.push_back(static_cast<uint32_t>(i));
      expected_alpha.push_back(std::min(alpha, 1.0));
    }
  }
  ASSERT_EQ(evaluated.full_points, expected_points);
  for (size_t j = 0; j < expected_alpha.size(); ++j) {
    EXPECT_NEAR(evaluated.full_point_blend_weights[j], expected_alpha[j], 1e-6) << "point " << expected_points[j];
  }
  // Without full values the answer is still the estimate.
  EXPECT_TRUE(evaluated.full_evaluation_needed);

  // The client's engine computes only those points.
  std::vector<float> values;
  for (uint32_t i : evaluated.full_points) values.insert(values.end(), &full[3 * i], &full[3 * i] + 3);
  const auto log_path = work_->path() / (kPmsc + ".misses");
  const CompletedMiss completed =
      client_->complete_miss(kPmsc, evaluated.model_version, pose, values, evaluated.full_points);
  EXPECT_TRUE(completed.logged);
  EXPECT_FALSE(completed.result.full_evaluation_needed);
  EXPECT_EQ(completed.result.full_points, evaluated.full_points);
  size_t j = 0;
  for (size_t i = 0; i < N; ++i) {
    const bool computed = j < expected_points.size() && expected_points[j] == i;
    const double alpha = computed ? expected_alpha[j++] : 0.0;
    for (int c = 0; c < 3; ++c) {
      const double expected = alpha * full[3 * i + c] + (1 - alpha) * evaluated.points.values[3 * i + c];
      ASSERT_NEAR(completed.result.points.values[3 * i + c], expected, 1e-5) << "point " << i;
    }
  }
  // The miss log keeps the partial frame as sent.
  auto records = misslog::read_records(log_path, 0, nullptr);
  ASSERT_TRUE(records.ok()) << records.error().message;
  ASSERT_FALSE(records->empty());
  EXPECT_EQ(records->back().full_points, evaluated.full_points);
  EXPECT_EQ(records->back().full_values, values);

  // Refusals name the field, with what was expected and what came.
  auto refusal = [&](std::vector<uint32_t> points, std::vector<float> wrong) {
    try {
      client_->complete_miss(kPmsc, evaluated.model_version, pose, wrong, points);
    } catch (const RpcError& e) {
      EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT) << e.what();
      return e.server_message();
    }
    ADD_FAILURE() << "bad full_points were accepted";
    return std::string();
  };
  const uint32_t first = evaluated.full_points[0];
  const std::vector<float> one_point(3, 0.0f);
  const std::string out_of_range = refusal({static_cast<uint32_t>(N)}, one_point);
  EXPECT_NE(out_of_range.find("full_points[0]: expected a point index below " + std::to_string(N) + " (the model's "
                              "points), got " + std::to_string(N)),
            std::string::npos)
      << out_of_range;
  std::vector<uint32_t> repeated = {first, first};
  const std::string not_ascending = refusal(repeated, std::vector<float>(6, 0.0f));
  EXPECT_NE(not_ascending.find("full_points[1]: expected an index above full_points[0] = " + std::to_string(first)),
            std::string::npos)
      << not_ascending;
  std::vector<uint32_t> missing(evaluated.full_points.begin() + 1, evaluated.full_points.end());
  std::vector<float> missing_values(values.begin() + 3, values.end());
  const std::string uncovered = refusal(missing, missing_values);
  EXPECT_NE(uncovered.find("full_points: point " + std::to_string(first) + " needs the full calculation"),
            std::string::npos)
      << uncovered;
  EXPECT_EQ(records->size(), misslog::read_records(log_path, 0, nullptr)->size()) << "a refusal was logged";
  // A value count that does not match the points (the wire allows it; the C++ client would not).
  v1::CompleteMissRequest request;
  request.mutable_model()->set_name(kPmsc);
  *request.mutable_key_values() = make_point_array(v.data(), static_cast<uint32_t>(v.size() / 3), 3);
  *request.mutable_full_values() = make_point_array(values.data(), 1, 3);
  request.mutable_full_points()->Add(evaluated.full_points.begin(), evaluated.full_points.end());
  auto stub = v1::PoseService::NewStub(grpc::CreateChannel(daemon_->address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  v1::CompleteMissResponse response;
  const grpc::Status status = stub->CompleteMiss(&context, request, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("full_values.point_count: expected " +
                                        std::to_string(evaluated.full_points.size()) + " points (one per full_points "
                                        "entry), got 1"),
            std::string::npos)
      << status.error_message();
}

TEST_F(ClientTest, SkeletonPosesEvaluateLikeTheCoreModel) {
  auto file = container::read_file(repo_->path() / kAnimationSpace / "1" / "model.anim");
  ASSERT_TRUE(file.ok());
  auto model = as::load(*file, kAnimationSpace);
  ASSERT_TRUE(model.ok()) << model.error().message;
  auto rows = file->double_matrix(container::sections::kSequenceBoneTransforms, 16 * model->bone_count());
  ASSERT_TRUE(rows.ok());
  std::vector<SkeletonPose> poses;
  std::vector<as::TransformList> globals;
  for (int f : {0, 17, 33}) {
    globals.push_back(as::pose_from_row(*rows, f, model->bone_count()));
    poses.push_back(testing::client_skeleton_pose(globals.back()));
  }
  SkinningOptions options;
  options.include_normals = true;
  const SkinningResult result = client_->evaluate_skeleton_pose(kAnimationSpace, poses, options);
  ASSERT_EQ(result.poses.size(), poses.size());
  for (size_t p = 0; p < poses.size(); ++p) {
    // The server sees float32 transforms; evaluate the core model with the same rounding.
    as::TransformList rounded = globals[p];
    for (auto& G : rounded) G = G.cast<float>().cast<double>();
    PointMatrix expected;
    as::evaluate(*model, rounded, expected);
    const SkinnedPose& got = result.poses[p];
    ASSERT_EQ(got.points.point_count, static_cast<uint32_t>(expected.rows()));
    for (Eigen::Index v = 0; v < expected.rows(); ++v) {
      for (int c = 0; c < 3; ++c) {
        ASSERT_NEAR(got.points.point(static_cast<uint32_t>(v))[static_cast<size_t>(c)], expected(v, c), 1e-4f)
            << "pose " << p << ", vertex " << v;
      }
      const auto n = got.normals.point(static_cast<uint32_t>(v));
      EXPECT_NEAR(std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), 1.0f, 1e-4f);
    }
  }
  SkinningOptions coarse;
  coarse.lod_level = 3;
  const SkinningResult level = client_->evaluate_skeleton_pose(kAnimationSpace, std::span(poses).first(1), coarse);
  const v1::ModelSummary summary = client_->describe_model(kAnimationSpace);
  EXPECT_LT(level.poses[0].points.point_count, result.poses[0].points.point_count) << "level 3 is coarser than level 0";
  EXPECT_TRUE(level.poses[0].normals.empty());
  EXPECT_GT(summary.versions(0).lod_level_count(), 3u);
}

TEST_F(ClientTest, ErrorsCarryTheCodeAndTheFieldTheServerNamed) {
  const KeyPoints keys = client_->describe_key_points(kPmsc);
  std::vector<float> v = keys.gather(frame(0));
  v.resize(v.size() - 3);
  try {
    client_->evaluate_key_points(kPmsc, {v, 3});
    FAIL() << "one key point too few was accepted";
  } catch (const RpcError& error) {
    EXPECT_EQ(error.code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_EQ(error.server_message(), "poses[0].key_values.point_count: expected " + std::to_string(keys.indices.size()) +
                                          " key points, got " + std::to_string(keys.indices.size() - 1));
    EXPECT_NE(std::string(error.what()).find("EvaluateKeyPoints failed: INVALID_ARGUMENT"), std::string::npos);
  }
  try {
    client_->describe_key_points("no-such-model");
    FAIL();
  } catch (const RpcError& error) {
    EXPECT_EQ(error.code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_NE(error.server_message().find("no-such-model"), std::string::npos);
  }
  // A pose whose values are not whole points never leaves the client.
  const std::vector<float> ragged(10, 0.0f);
  EXPECT_THROW(client_->evaluate_key_points(kPmsc, {ragged, 3}), std::invalid_argument);
  SkeletonPose bad;
  bad.transforms.assign(13, 0.0f);
  EXPECT_THROW(client_->evaluate_skeleton_pose(kAnimationSpace, std::span(&bad, 1)), std::invalid_argument);
}

TEST_F(ClientTest, EveryCallHasADeadline) {
  ClientOptions options;
  // A second in the past: well beyond gRPC's cached clock, so the call cannot slip through.
  options.deadline = std::chrono::milliseconds(-1000);
  Client hurried(daemon_->address(), options);
  try {
    hurried.list_models();
    FAIL() << "a call with a deadline already past succeeded";
  } catch (const RpcError& error) {
    EXPECT_EQ(error.code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  }
}

TEST_F(ClientTest, TheReadmesCppTourRunsAgainstTheDemo) {
  // The tour relights the demo's cornell and plays arm-articulated: added here alone, since the
  // other tests' daemon would load them for nothing.
  ASSERT_TRUE(testing::write_demo_illumination(repo_->path()).ok());
  client_->load_model("cornell", 1);
  ASSERT_TRUE(testing::write_demo_articulated(repo_->path()).ok());
  client_->load_model(std::string(demo::kDemoArticulatedModelName), 1);
  // The tour's basis cache goes to the test's folder, not the home folder.
  const std::string command = "ANIMSPACE_BASIS_CACHE=" + (work_->path() / "bases").string() + " " +
                              harness::program_path("animspace-client-tour").string() + " " + daemon_->address() + " " +
                              (work_->path() / "tour.png").string() + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[512];
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
  ASSERT_EQ(pclose(pipe), 0) << output;
  const auto lod_levels = client_->describe_model(kAnimationSpace).versions(0).lod_level_count();
  EXPECT_NE(output.find("streamed 100 frames"), std::string::npos) << output;
  // Answers as coordinates (issue #36), reconstructed by the client from the cached basis.
  EXPECT_NE(output.find(" values reconstructed into 1154 points, within "), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::is_empty(work_->path() / "bases" / "arm-pmsc")) << "no basis cached";
  // Issue #51: the articulated arm's answer, its coordinates and error against the rig's pose, next
  // to arm-pmsc's estimate of the same unseen swing.
  const size_t articulated = output.find("articulated: ");
  ASSERT_NE(articulated, std::string::npos) << output;
  float articulated_error = 0, linear_error = 0;
  ASSERT_EQ(std::sscanf(output.c_str() + output.find("largest error ", articulated), "largest error %g (arm-pmsc's estimate: %g)",
                        &articulated_error, &linear_error),
            2)
      << output.substr(articulated, 200);
  EXPECT_LT(articulated_error, 0.5f * linear_error) << output.substr(articulated, 200);
  EXPECT_FALSE(std::filesystem::is_empty(work_->path() / "bases" / "arm-articulated")) << "no basis cached";
  EXPECT_NE(output.find("arm-articulated's basis: skinned, "), std::string::npos) << output;  // issue #51 item 4
  EXPECT_NE(output.find("skinned "), std::string::npos) << output;
  EXPECT_NE(output.find("LOD level "), std::string::npos) << output;
  EXPECT_NE(output.find("relit by a light at (0.45, 0.44, 0.45): HIT, "), std::string::npos) << output;
  EXPECT_NE(output.find("relit by a light at (0.28, 0.05, 0.50): MISS, "), std::string::npos) << output;
  // The same light ten times brighter: the same verdict (a tolerance relative to each frame).
  const size_t inside = output.find("relit by a light at (0.45, 0.44, 0.45): HIT, ");
  ASSERT_NE(inside, std::string::npos) << output;
  const size_t next_line = output.find('\n', inside) + 1;
  EXPECT_EQ(output.compare(next_line, 26, "  ten times brighter: HIT,"), 0) << output.substr(inside, 300);
  EXPECT_NE(output.find("no thumbnail: "), std::string::npos) << "this daemon runs without a renderer: " << output;
  EXPECT_GT(lod_levels, 1u);
  // The unseen pose misses and is completed with the rig's real full pose, which the server accepts
  // (it refuses full values that do not repeat the key values) and logs.
  EXPECT_NE(output.find("completed: MISS, logged for retraining: yes"), std::string::npos) << output;
  // Check points (issue #35): the dent the key points alone call a HIT is overturned.
  const size_t dent = output.find("dent: HIT from the key points alone");
  ASSERT_NE(dent, std::string::npos) << output;
  const std::string dent_line = output.substr(dent, output.find('\n', dent) - dent);
  EXPECT_TRUE(dent_line.find("MISS with its check points") != std::string::npos ||
              dent_line.find("BLEND with its check points") != std::string::npos)
      << dent_line;
  // Local fail-through completes a pose whose forearm alone left the training set.
  EXPECT_NE(output.find("local fail-through: "), std::string::npos) << output;
  EXPECT_EQ(output.find("local fail-through: 1154 of 1154"), std::string::npos) << "nothing was local: " << output;
}

// Issue #21: `--help` was resolved as a host name. Every program answers it.
TEST_F(ClientTest, TheTourAnswersHelpAndRefusesUnknownOptions) {
  auto run = [](const std::string& arguments, int* status) {
    FILE* pipe = popen((harness::program_path("animspace-client-tour").string() + " " + arguments + " 2>&1").c_str(), "r");
    std::string output;
    char buffer[512];
    while (pipe != nullptr && fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
    *status = pipe != nullptr ? pclose(pipe) : -1;
    return output;
  };
  int status = -1;
  const std::string help = run("--help", &status);
  EXPECT_EQ(status, 0) << help;
  EXPECT_EQ(help.rfind("usage: animspace-client-tour [SERVER [PNG]]", 0), 0u) << help;
  const std::string unknown = run("--frobnicate", &status);
  EXPECT_NE(status, 0) << unknown;
  EXPECT_NE(unknown.find("unknown option '--frobnicate'"), std::string::npos) << unknown;
}

}  // namespace
}  // namespace animspace
