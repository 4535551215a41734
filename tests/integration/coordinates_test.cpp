// Issue #36, coordinates on the wire, over real gRPC against the real animspaced: answers asked for
// as POINT_ENCODING_COORDINATES, reconstructed by the C++ client (clients/cpp/coordinates.h), are
// the float32 answers within the bound the header states — computed here, in double, from the
// model file read independently — with the same verdicts; GetBasis reassembles the file's mean and
// basis; the basis cache never reconstructs with a basis the answer did not name.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <fstream>

#include <gtest/gtest.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "clients/cpp/client.h"
#include "clients/cpp/coordinates.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/common/atomic_file.h"
#include "core/common/point_codec.h"
#include "core/common/sha256.h"
#include "core/container/crc32.h"
#include "core/container/model_container.h"
#include "core/demo/bending_arm.h"
#include "core/demo/demo_repository.h"
#include "core/pmsc/coordinates.h"
#include "core/pmsc/pmsc_io.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;

// The arm over elbow 0–50° (the narrow range the soft cache is trained on), with or without the
// rigid alignment (the model then moves each estimate to the world).
container::ModelContainer arm_model(bool aligned, double elbow_step_deg) {
  return testing::narrow_arm_model({}, elbow_step_deg, aligned);
}

class CoordinatesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    template_repo_ = new TempDir();
    ASSERT_TRUE(testing::write_demo_repository(template_repo_->path()).ok());
    testing::write_model(template_repo_->path(), "bend", 1, arm_model(false, 5));
    testing::write_model(template_repo_->path(), "bend-aligned", 1, arm_model(true, 5));
  }
  static void TearDownTestSuite() {
    delete template_repo_;
    template_repo_ = nullptr;
  }

  void SetUp() override {
    repo_ = work_.path() / "repo";
    std::filesystem::copy(template_repo_->path(), repo_, std::filesystem::copy_options::recursive);
    // 256 KiB messages: GetBasis cuts the arm's basis (~150 KiB of values) into 64 KiB chunks.
    daemon_ = std::make_unique<DaemonProcess>(
        std::vector<std::string>{"--model-repository", repo_.string(), "--max-message-bytes", "262144"}, work_.path());
    client_ = std::make_unique<Client>(daemon_->address());
    ASSERT_TRUE(testing::wait_until_serving(*client_));
  }

  // The served file's model, read here rather than asked of the daemon.
  pmsc::PmscModel model_file(const std::string& name, int version = 1) const {
    auto file = container::read_file(repo_ / name / std::to_string(version) / "model.anim");
    EXPECT_TRUE(file.ok());
    auto model = pmsc::load(*file, name);
    EXPECT_TRUE(model.ok()) << model.error().message;
    return std::move(*model);
  }

  // Key values of the arm posed by the expensive rig, in the model's key order.
  static std::vector<float> key_values(const KeyPoints& keys, double elbow_deg, double shoulder_deg) {
    static const demo::ArmRig rig = demo::make_arm_rig();
    const Eigen::VectorXf frame = testing::expensive_arm_frame(rig, elbow_deg, shoulder_deg);
    return keys.gather({frame.data(), static_cast<size_t>(frame.size())});
  }

  static inline TempDir* template_repo_ = nullptr;
  TempDir work_;
  std::filesystem::path repo_;
  std::unique_ptr<DaemonProcess> daemon_;
  std::unique_ptr<Client> client_;
};

// The header's bound between a client reconstruction and the float32 answer, value by value.
// With a basis fetched as FLOAT16 (`float16`), each value is within 2^-11 of its size: the bound
// before the alignment is poses.proto's for FLOAT16.
void expect_within_bound(const pmsc::PmscModel& m, const SubspaceCoordinates& c, const std::vector<float>& client,
                         const std::vector<float>& server, const std::string& what, bool float16 = false) {
  ASSERT_EQ(client.size(), server.size()) << what;
  const Eigen::VectorXd p = Eigen::Map<const Eigen::VectorXf>(c.p.data(), static_cast<long>(c.p.size())).cast<double>();
  const Eigen::VectorXd size = m.mean.cast<double>().cwiseAbs() + m.basis.cast<double>().cwiseAbs() * p.cwiseAbs();
  const double gamma = pmsc::coordinates_rounding_bound(m.basis_size());
  const Eigen::VectorXd before_alignment =
      float16 ? Eigen::VectorXd(((gamma + 0x1p-11) * (1 + 0x1p-10) * size).array() + 0x1p-24 * (1 + p.cwiseAbs().sum()))
              : Eigen::VectorXd(gamma * size);
  for (size_t i = 0; i < client.size(); ++i) {
    double allowed = before_alignment(static_cast<long>(i));
    if (m.aligned) {
      const long point = static_cast<long>(i) / 3;
      // x, the point in the aligned frame: the answer less the translation (R keeps its norm).
      const Eigen::Vector3d x = Eigen::Vector3d(server[3 * point], server[3 * point + 1], server[3 * point + 2]) -
                                Eigen::Vector3d(c.translation[0], c.translation[1], c.translation[2]);
      allowed = before_alignment.segment(3 * point, 3).norm() + pmsc::aligned_rounding_bound() * x.norm() +
                pmsc::translation_rounding_bound() * std::abs(static_cast<double>(server[i]));
    }
    ASSERT_LE(std::abs(static_cast<double>(client[i]) - server[i]), allowed) << what << ", value " << i;
  }
}

TEST_F(CoordinatesTest, ReconstructedAnswersAreTheFloat32AnswersWithinTheStatedBound) {
  BasisCache cache(work_.path() / "bases");
  for (const std::string name : {"bend", "bend-aligned"}) {
    const pmsc::PmscModel m = model_file(name);
    ASSERT_EQ(m.aligned, name == "bend-aligned");
    const KeyPoints keys = client_->describe_key_points(name);
    // Inside the trained range (hits), past it, and poses no arm makes — key points moved by a
    // tenth of the arm's length — which the client must complete (blends and misses).
    std::vector<std::vector<float>> values;
    for (double elbow : {3.0, 17.0, 31.0, 44.0, 70.0, 95.0}) values.push_back(key_values(keys, elbow, 10));
    for (float moved : {0.05f, 0.2f}) {
      values.push_back(key_values(keys, 25, 0));
      for (size_t k = 0; k < values.back().size(); k += 7) values.back()[k] += moved;
    }
    std::vector<KeyPointPose> poses;
    for (const auto& v : values) poses.push_back({v, keys.channel_count});
    EvaluateOptions float32;
    EvaluateOptions coordinates;
    coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
    const auto expected = client_->evaluate_key_points_batch(name, poses, float32);
    auto answered = client_->evaluate_key_points_batch(name, poses, coordinates);
    // A stream answers the same.
    StreamOptions stream_options;
    stream_options.points_encoding = v1::POINT_ENCODING_COORDINATES;
    auto stream = client_->open_stream(name, stream_options);
    for (size_t i = 0; i < poses.size(); ++i) ASSERT_TRUE(stream->write(poses[i], i));
    stream->writes_done();
    std::vector<PoseResult> streamed;
    while (auto result = stream->read()) streamed.push_back(std::move(*result));
    stream->finish();
    ASSERT_EQ(streamed.size(), poses.size());

    bool saw_hit = false;
    bool saw_completion = false;
    for (size_t i = 0; i < poses.size(); ++i) {
      for (PoseResult* result : {&answered[i], &streamed[i]}) {
        const std::string what = name + " pose " + std::to_string(i);
        EXPECT_EQ(result->status, expected[i].status) << what;
        EXPECT_EQ(result->key_point_error, expected[i].key_point_error) << what;
        EXPECT_EQ(result->full_evaluation_needed, expected[i].full_evaluation_needed) << what;
        // No server engine here: every answer is the client's to reconstruct, and carries no points.
        ASSERT_TRUE(result->coordinates.present) << what;
        EXPECT_TRUE(result->points.empty()) << what;
        EXPECT_EQ(result->coordinates.p.size(), static_cast<size_t>(m.basis_size())) << what;
        EXPECT_EQ(result->coordinates.rotation.size(), m.aligned ? 9u : 0u) << what;
        ASSERT_TRUE(cache.reconstruct(*client_, name, *result)) << what;
        expect_within_bound(m, result->coordinates, result->points.values, expected[i].points.values, what);
      }
      saw_hit = saw_hit || expected[i].status == v1::CACHE_STATUS_HIT;
      saw_completion = saw_completion || expected[i].full_evaluation_needed;
    }
    EXPECT_TRUE(saw_hit) << name << ": no pose hit";
    EXPECT_TRUE(saw_completion) << name << ": no pose needed the client's completion";
  }
  // One download per model, whatever the number of answers.
  EXPECT_EQ(cache.fetch_count(), 2u);
}

TEST_F(CoordinatesTest, AnswersTheServerComputesStillComeAsPoints) {
  // arm-pmsc-engine fails through to its animation-space engine: a pose far outside the demo
  // animation, sent with its skeleton pose, is answered with the engine's points.
  const std::string name(demo::kDemoPmscEngineModelName);
  auto file = container::read_file(repo_ / name / "1" / "model.anim");
  ASSERT_TRUE(file.ok());
  auto engine = animation_space::load(*file, name);
  ASSERT_TRUE(engine.ok()) << engine.error().message;
  const demo::ArmRig rig = demo::make_arm_rig();
  demo::ArmPose far;
  far.elbow_angle_rad = 2.8;
  far.shoulder_angle_rad = 1.7;
  far.forearm_twist_rad = 1.0;
  const auto G = demo::bone_transforms(far, rig.options);
  const animation_space::TransformList globals{animation_space::Transform::Identity(), G[demo::kUpperArm],
                                               G[demo::kForearm]};
  PointMatrix posed;
  animation_space::evaluate(*engine, globals, posed);
  const KeyPoints keys = client_->describe_key_points(name);
  const std::vector<float> values = keys.gather({posed.data(), static_cast<size_t>(posed.size())});
  const SkeletonPose skeleton = testing::client_skeleton_pose(globals);
  EvaluateOptions coordinates;
  coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
  const PoseResult result = client_->evaluate_key_points(name, {values, keys.channel_count, &skeleton}, coordinates);
  ASSERT_EQ(result.status, v1::CACHE_STATUS_MISS) << "e_key " << result.key_point_error;
  EXPECT_FALSE(result.full_evaluation_needed);
  EXPECT_FALSE(result.coordinates.present);
  // A miss is the engine's pose itself (float transforms on the wire: float tolerance).
  ASSERT_EQ(result.points.values.size(), static_cast<size_t>(posed.size()));
  for (long i = 0; i < posed.size(); ++i) {
    ASSERT_NEAR(result.points.values[static_cast<size_t>(i)], posed.data()[i], 1e-4f) << "value " << i;
  }
}

TEST_F(CoordinatesTest, GetBasisSendsTheFilesMeanAndBasisInChunks) {
  const pmsc::PmscModel m = model_file("bend");
  const BasisData data = client_->get_basis("bend");
  EXPECT_GT(data.chunk_count, 1u) << "256 KiB messages should cut the basis";
  EXPECT_EQ(data.model_version, 1u);
  EXPECT_EQ(data.basis_size, static_cast<uint32_t>(m.basis_size()));
  ASSERT_EQ(data.values.size(), static_cast<size_t>(m.mean.size() * (m.basis_size() + 1)));
  EXPECT_EQ(Eigen::Map<const Eigen::VectorXf>(data.values.data(), m.mean.size()), m.mean);
  EXPECT_EQ(Eigen::Map<const Eigen::MatrixXf>(data.values.data() + m.mean.size(), m.mean.size(), m.basis_size()),
            m.basis);
  EXPECT_EQ(data.basis_checksum, pmsc::basis_checksum(m.mean, m.basis));
  EXPECT_NO_THROW(make_basis("bend", data));

  EXPECT_EQ(testing::code_of([&] { client_->get_basis("absent"); }), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(testing::code_of([&] { client_->get_basis("bend", 9); }), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(testing::code_of([&] { client_->get_basis(std::string(demo::kDemoModelName)); }),
            grpc::StatusCode::FAILED_PRECONDITION);
}

// Issue #53: GetBasis in float16 — half the bytes, each value the float32 one rounded to nearest
// binary16, checked against the digest of what was sent; answers reconstructed with it are the
// float32 answers within the bound poses.proto states for FLOAT16.
TEST_F(CoordinatesTest, AFloat16BasisIsHalfTheBytesAndReconstructsWithinItsStatedBound) {
  for (const std::string name : {"bend", "bend-aligned"}) {
    const pmsc::PmscModel m = model_file(name);
    const BasisData exact = client_->get_basis(name);
    const BasisData half = client_->get_basis(name, 0, {}, v1::POINT_ENCODING_FLOAT16);
    EXPECT_EQ(exact.values_encoding, v1::POINT_ENCODING_FLOAT32);
    ASSERT_EQ(half.values_encoding, v1::POINT_ENCODING_FLOAT16) << name;
    EXPECT_LT(half.bytes_received, exact.bytes_received * 55 / 100) << name;
    ASSERT_EQ(half.values.size(), exact.values.size());
    double largest = 0;
    for (size_t i = 0; i < exact.values.size(); ++i) {
      const float rounded = point_codec::half_to_float(point_codec::float_to_half(exact.values[i]));
      ASSERT_EQ(half.values[i], rounded) << name << ", value " << i;
      largest = std::max(largest, std::abs(static_cast<double>(rounded) - exact.values[i]));
    }
    EXPECT_EQ(half.values_max_error, static_cast<float>(largest)) << name;
    EXPECT_EQ(half.basis_checksum, exact.basis_checksum) << "the float32 basis's name, which answers carry";
    const Basis basis = make_basis(name, half);
    EXPECT_EQ(basis.values_max_error, half.values_max_error);

    const KeyPoints keys = client_->describe_key_points(name);
    std::vector<std::vector<float>> values;
    for (double elbow : {3.0, 31.0, 70.0}) values.push_back(key_values(keys, elbow, 10));
    std::vector<KeyPointPose> poses;
    for (const auto& v : values) poses.push_back({v, keys.channel_count});
    EvaluateOptions coordinates;
    coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
    const auto expected = client_->evaluate_key_points_batch(name, poses, {});
    auto answered = client_->evaluate_key_points_batch(name, poses, coordinates);
    for (size_t i = 0; i < poses.size(); ++i) {
      ASSERT_TRUE(answered[i].coordinates.present);
      reconstruct(basis, answered[i], answered[i].points);
      expect_within_bound(m, answered[i].coordinates, answered[i].points.values, expected[i].points.values,
                          name + " pose " + std::to_string(i), true);
    }
  }
  EXPECT_EQ(testing::code_of([&] { client_->get_basis("bend", 0, {}, v1::POINT_ENCODING_FIXED16); }),
            grpc::StatusCode::INVALID_ARGUMENT);
}

// Issue #51 item 4: an articulated model's basis asked for COMPACT comes SKINNED — a fraction of
// the values — and is the same basis: expanded here by poses.proto's definition it is the file's
// mean and basis bit for bit, answers reconstructed with it are the float32 answers within the
// dense bound, and the cache keeps it skinned (ASBASIS2) and reads it back without a download. A
// linear model's COMPACT is DENSE, and SKINNED is refused naming the field.
TEST_F(CoordinatesTest, AnArticulatedBasisComesSkinnedAndIsTheSameBasis) {
  ASSERT_TRUE(testing::write_demo_articulated(repo_).ok());
  const std::string name(demo::kDemoArticulatedModelName);
  client_->load_model(name, 1);
  const pmsc::PmscModel m = model_file(name);
  const BasisData dense = client_->get_basis(name);
  const BasisData compact = client_->get_basis(name, 0, {}, v1::POINT_ENCODING_FLOAT32, v1::BASIS_LAYOUT_COMPACT);
  EXPECT_EQ(dense.layout, v1::BASIS_LAYOUT_DENSE);
  ASSERT_EQ(compact.layout, v1::BASIS_LAYOUT_SKINNED);
  ASSERT_EQ(compact.subspace_bone_count, static_cast<uint32_t>(m.bone_count));
  EXPECT_GT(compact.chunk_count, 0u);
  EXPECT_LT(compact.values.size(), dense.values.size() / 2);
  EXPECT_EQ(compact.basis_checksum, dense.basis_checksum);
  EXPECT_EQ(compact.basis_sha256, dense.basis_sha256);

  const long N = m.point_count, K = compact.influences_per_point, B = m.bone_count;
  const long rows = 3 * N, skinning = 12 * B;
  Eigen::MatrixXf A = Eigen::MatrixXf::Zero(rows, m.basis_size());
  const float* slot = compact.values.data() + rows;
  for (long i = 0; i < N; ++i) {
    for (long k = 0; k < K; ++k, slot += 5) {
      const auto j = static_cast<long>(slot[0]);
      ASSERT_EQ(static_cast<float>(j), slot[0]) << "point " << i << " slot " << k;
      ASSERT_LT(j, B);
      for (int a = 0; a < 3; ++a) {
        for (int c = 0; c < 4; ++c) {
          if (slot[1 + c] != 0) A(3 * i + a, 12 * j + 4 * a + c) = slot[1 + c];
        }
      }
    }
  }
  A.rightCols(m.basis_size() - skinning) =
      Eigen::Map<const Eigen::MatrixXf>(slot, rows, m.basis_size() - skinning);
  EXPECT_EQ(Eigen::Map<const Eigen::VectorXf>(compact.values.data(), rows), m.mean);
  EXPECT_EQ(A, m.basis);
  const Basis basis = make_basis(name, compact);  // checks both digests through its own expansion
  // In float16 too: each value the float32 one rounded (the bone numbers exactly), checked as sent.
  const BasisData half = client_->get_basis(name, 0, {}, v1::POINT_ENCODING_FLOAT16, v1::BASIS_LAYOUT_COMPACT);
  ASSERT_EQ(half.layout, v1::BASIS_LAYOUT_SKINNED);
  ASSERT_EQ(half.values.size(), compact.values.size());
  for (size_t i = 0; i < half.values.size(); ++i) {
    ASSERT_EQ(half.values[i], point_codec::half_to_float(point_codec::float_to_half(compact.values[i]))) << i;
  }
  EXPECT_NE(make_basis(name, half).skinned, nullptr);
  ASSERT_NE(basis.skinned, nullptr);
  EXPECT_LT(basis.bytes() * 2, make_basis(name, dense).bytes());

  const KeyPoints keys = client_->describe_key_points(name);
  std::vector<KeyPointPose> poses;
  std::vector<std::vector<float>> values;
  for (double elbow : {5.0, 30.0, 60.0, 110.0}) values.push_back(key_values(keys, elbow, 15));
  for (const auto& v : values) poses.push_back({v, keys.channel_count});
  EvaluateOptions coordinates;
  coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
  const auto expected = client_->evaluate_key_points_batch(name, poses, {});
  auto answered = client_->evaluate_key_points_batch(name, poses, coordinates);
  int reconstructed = 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    if (!answered[i].coordinates.present) continue;  // computed by the server's engine: points
    reconstruct(basis, answered[i], answered[i].points);
    expect_within_bound(m, answered[i].coordinates, answered[i].points.values, expected[i].points.values,
                        "pose " + std::to_string(i));
    ++reconstructed;
  }
  EXPECT_GT(reconstructed, 0);

  const auto directory = work_.path() / "bases";
  const uint64_t checksum = compact.basis_checksum;
  {
    BasisCache cache(directory);
    EXPECT_EQ(cache.get(*client_, name, 1, checksum)->skinned != nullptr, true);
    EXPECT_EQ(cache.fetch_count(), 1u);
    EXPECT_EQ(cache.memory_bytes(), basis.bytes());
  }
  const auto file = BasisCache(directory).file_of(name, 1, checksum);
  const auto bytes = read_regular_file(file);
  ASSERT_TRUE(bytes.ok());
  EXPECT_EQ(bytes->substr(0, 8), "ASBASIS2");
  {
    BasisCache cache(directory);  // a new process: the skinned file, verified, is enough
    EXPECT_NE(cache.get(*client_, name, 1, checksum)->skinned, nullptr);
    EXPECT_EQ(cache.fetch_count(), 0u);
  }

  const BasisData linear = client_->get_basis("bend", 0, {}, v1::POINT_ENCODING_FLOAT32, v1::BASIS_LAYOUT_COMPACT);
  EXPECT_EQ(linear.layout, v1::BASIS_LAYOUT_DENSE);
  try {
    client_->get_basis("bend", 0, {}, v1::POINT_ENCODING_FLOAT32, v1::BASIS_LAYOUT_SKINNED);
    ADD_FAILURE() << "a linear model's basis came SKINNED";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_NE(std::string(e.what()).find("layout: model 'bend' version 1 has no SKINNED layout"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(testing::code_of([&] {
              client_->get_basis("bend", 0, {}, v1::POINT_ENCODING_FLOAT32, static_cast<v1::BasisLayout>(9));
            }),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(CoordinatesTest, TheCacheReusesVerifiedFilesAndNeverReconstructsWithAnotherBasis) {
  const KeyPoints keys = client_->describe_key_points("bend");
  const std::vector<float> values = key_values(keys, 20, 0);
  EvaluateOptions coordinates;
  coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
  const PoseResult answer = client_->evaluate_key_points("bend", {values, keys.channel_count}, coordinates);
  ASSERT_TRUE(answer.coordinates.present);
  const auto directory = work_.path() / "bases";
  {
    BasisCache cache(directory);
    PoseResult result = answer;
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    EXPECT_EQ(cache.fetch_count(), 1u);
  }
  const auto file = BasisCache(directory).file_of("bend", 1, answer.coordinates.basis_checksum);
  ASSERT_TRUE(std::filesystem::exists(file));
  {
    BasisCache cache(directory);  // a new process: the file, verified, is enough
    PoseResult result = answer;
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    EXPECT_EQ(cache.fetch_count(), 0u);
  }
  {
    // One flipped byte of the basis: the file is refused, and fetched again.
    std::fstream bytes(file, std::ios::in | std::ios::out | std::ios::binary);
    bytes.seekp(static_cast<std::streamoff>(std::filesystem::file_size(file) - 5));
    bytes.put('\x5a');
  }
  {
    BasisCache cache(directory);
    PoseResult result = answer;
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    EXPECT_EQ(cache.fetch_count(), 1u);
  }
  {
    // An answer naming a basis its version does not have is refused, not reconstructed.
    BasisCache cache(directory);
    PoseResult result = answer;
    result.coordinates.basis_checksum ^= 1;
    EXPECT_THROW(cache.reconstruct(*client_, "bend", result), std::runtime_error);
    EXPECT_TRUE(result.points.empty());
    // And a basis given by hand for the wrong answer is refused too.
    const auto basis = cache.get(*client_, "bend", 1, answer.coordinates.basis_checksum);
    Points points;
    EXPECT_THROW(reconstruct(*basis, result, points), std::runtime_error);
  }
}

// Makes crc32(bytes[begin, end)) equal `target` by choosing the four bytes at `patch_at` (inside
// the range): the CRC is affine in those 32 bits over GF(2), and that map is invertible, so the
// 32 columns and one elimination give them — what anyone can do to a CRC-checked file.
void forge_crc32(std::string& bytes, size_t begin, size_t end, size_t patch_at, uint32_t target) {
  const auto crc = [&] { return container::crc32(std::string_view(bytes).substr(begin, end - begin)); };
  std::memset(bytes.data() + patch_at, 0, 4);
  const uint32_t base = crc();
  std::vector<uint32_t> columns(32);
  for (int bit = 0; bit < 32; ++bit) {
    bytes[patch_at + bit / 8] = static_cast<char>(1 << (bit % 8));
    columns[static_cast<size_t>(bit)] = crc() ^ base;
    bytes[patch_at + bit / 8] = 0;
  }
  // Solve Σ x_bit · columns[bit] = target ^ base: rows are the CRC's bits, tracked as
  // (column value, the set of patch bits that made it).
  std::vector<std::pair<uint32_t, uint32_t>> basis;  // reduced columns with their combinations
  for (uint32_t bit = 0; bit < 32; ++bit) {
    uint32_t value = columns[bit], made_of = 1u << bit;
    for (const auto& [v, m] : basis) {
      if ((value ^ v) < value) value ^= v, made_of ^= m;  // clear v's leading bit from value
    }
    if (value != 0) basis.emplace_back(value, made_of);
    std::sort(basis.begin(), basis.end(), std::greater<>());
  }
  ASSERT_EQ(basis.size(), 32u) << "four consecutive bytes always reach every CRC";
  uint32_t wanted = target ^ base, patch = 0;
  for (const auto& [v, m] : basis) {
    if ((wanted ^ v) < wanted) wanted ^= v, patch ^= m;
  }
  ASSERT_EQ(wanted, 0u);
  for (int byte = 0; byte < 4; ++byte) bytes[patch_at + static_cast<size_t>(byte)] = static_cast<char>(patch >> (8 * byte));
  ASSERT_EQ(crc(), target);
}

// Issue #54 item 8: a cached basis with one point moved by 0.5 and its CRC forged to match — which
// the CRC alone accepted — is refused because its SHA-256 is not the server's, fetched again, and
// the file overwritten with the true basis.
TEST_F(CoordinatesTest, ACachedBasisWithAForgedCrcIsRefusedByTheServersDigest) {
  const KeyPoints keys = client_->describe_key_points("bend");
  ASSERT_EQ(keys.basis_sha256.size(), 32u);
  const std::vector<float> values = key_values(keys, 20, 0);
  EvaluateOptions coordinates;
  coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
  const PoseResult answer = client_->evaluate_key_points("bend", {values, keys.channel_count}, coordinates);
  ASSERT_TRUE(answer.coordinates.present);
  EXPECT_EQ(keys.basis_checksum, answer.coordinates.basis_checksum);
  const auto directory = work_.path() / "bases";
  PoseResult truth = answer;
  ASSERT_TRUE(BasisCache(directory).reconstruct(*client_, "bend", truth));
  const auto file = BasisCache(directory).file_of("bend", 1, answer.coordinates.basis_checksum);
  auto original = read_whole_file(file);
  ASSERT_TRUE(original.ok());
  EXPECT_EQ(sha256(std::string_view(*original).substr(40)), keys.basis_sha256)
      << "the digest is SHA-256 of the values as sent";

  std::string forged = *original;
  uint32_t n = 0, d = 0;
  std::memcpy(&n, forged.data() + 8, 4);
  std::memcpy(&d, forged.data() + 12, 4);
  const size_t mean_end = 40 + 4 * size_t{n} * d;
  float x = 0;
  std::memcpy(&x, forged.data() + 40, 4);
  x += 0.5f;
  std::memcpy(forged.data() + 40, &x, 4);
  forge_crc32(forged, 40, mean_end, mean_end - 4, static_cast<uint32_t>(answer.coordinates.basis_checksum >> 32));
  testing::write_text_file(file, forged);
  {
    BasisCache cache(directory);
    PoseResult result = answer;
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    EXPECT_EQ(result.points.values, truth.points.values);
    EXPECT_EQ(cache.refused_copy_count(), 1u);
    EXPECT_EQ(cache.fetch_count(), 1u);
  }
  EXPECT_EQ(*read_whole_file(file), *original);
  {
    BasisCache cache(directory);  // the true copy: used, one DescribeKeyPoints instead of GetBasis
    PoseResult result = answer;
    ASSERT_TRUE(cache.reconstruct(*client_, "bend", result));
    EXPECT_EQ(cache.fetch_count(), 0u);
    EXPECT_EQ(cache.refused_copy_count(), 0u);
  }
}

TEST_F(CoordinatesTest, AVersionSwapIsFollowedNotMixed) {
  BasisCache cache(work_.path() / "bases");
  const KeyPoints keys = client_->describe_key_points("bend");
  const std::vector<float> values = key_values(keys, 20, 0);
  EvaluateOptions coordinates;
  coordinates.points_encoding = v1::POINT_ENCODING_COORDINATES;
  PoseResult before = client_->evaluate_key_points("bend", {values, keys.channel_count}, coordinates);
  ASSERT_EQ(before.model_version, 1u);

  // Version 2 trained on other frames: another basis, served from now on.
  testing::write_model(repo_, "bend", 2, arm_model(false, 2.5));
  client_->load_model("bend", 2);
  const KeyPoints keys2 = client_->describe_key_points("bend");
  const std::vector<float> values2 = key_values(keys2, 20, 0);
  PoseResult after = client_->evaluate_key_points("bend", {values2, keys2.channel_count}, coordinates);
  ASSERT_EQ(after.model_version, 2u);
  ASSERT_NE(after.coordinates.basis_checksum, before.coordinates.basis_checksum);
  ASSERT_TRUE(cache.reconstruct(*client_, "bend", after));
  ASSERT_TRUE(cache.reconstruct(*client_, "bend", before));  // version 1 is still served: its own basis
  EXPECT_EQ(cache.fetch_count(), 2u);
  const EvaluateOptions float32;
  const PoseResult expected = client_->evaluate_key_points("bend", {values2, keys2.channel_count}, float32);
  expect_within_bound(model_file("bend", 2), after.coordinates, after.points.values, expected.points.values,
                      "version 2");

  // A cache with room for one basis in memory keeps the one used last: the other is evicted and
  // fetched again (no disk to fall back on), and every reconstruction is still the right one.
  BasisCache one(std::filesystem::path{}, 1);
  PoseResult first = after, second = before;
  ASSERT_TRUE(one.reconstruct(*client_, "bend", first));
  ASSERT_TRUE(one.reconstruct(*client_, "bend", second));
  EXPECT_EQ(one.memory_count(), 1u);
  EXPECT_EQ(one.memory_bytes(), sizeof(float) * static_cast<size_t>(model_file("bend", 1).mean.size() +
                                                                    model_file("bend", 1).basis.size()));
  ASSERT_TRUE(one.reconstruct(*client_, "bend", second));
  EXPECT_EQ(one.fetch_count(), 2u) << "the basis used last stays";
  ASSERT_TRUE(one.reconstruct(*client_, "bend", first));
  EXPECT_EQ(one.fetch_count(), 3u) << "the evicted one is fetched again";
  EXPECT_EQ(first.points.values, after.points.values);
  EXPECT_EQ(second.points.values, before.points.values);

  // Version 1 unloaded: an old answer can no longer be reconstructed by a cache without it.
  client_->unload_model("bend", 1);
  BasisCache empty(std::filesystem::path{});
  PoseResult old = before;
  old.points = {};
  EXPECT_EQ(testing::code_of([&] { empty.reconstruct(*client_, "bend", old); }), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(old.points.empty());
}

}  // namespace
}  // namespace animspace
