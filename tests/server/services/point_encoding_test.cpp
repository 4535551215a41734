// PoseService answers in the encoding a request asks for (PointArray.encoding): the same verdicts
// as float32, points exactly 2·N·D bytes that decode — by this file's own decoder, written from
// the proto's definition — within the reported max_error of the float32 answer, and within the
// bound core/common/point_codec.h states. Inputs in 16-bit encodings are read as the values they
// decode to.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "animspace/v1/poses.grpc.pb.h"
#include "core/container/model_container.h"
#include "core/container/sections.h"
#include "core/demo/demo_repository.h"
#include "core/pmsc/pmsc_io.h"
#include "tests/server/support/in_process_server.h"
#include "tests/support/test_support.h"

namespace animspace {
namespace {

using testing::InProcessServer;
using testing::TempDir;
using Code = grpc::StatusCode;

const std::string kPmsc(demo::kDemoPmscModelName);

v1::PointArray float32_array(const float* values, uint32_t count, uint32_t channels) {
  v1::PointArray a;
  a.set_point_count(count);
  a.set_channel_count(channels);
  a.set_data(values, size_t{count} * channels * sizeof(float));
  return a;
}

std::vector<float> float32_values(const v1::PointArray& a) {
  std::vector<float> out(a.data().size() / 4);
  if (!out.empty()) std::memcpy(out.data(), a.data().data(), a.data().size());
  return out;
}

std::vector<uint16_t> uint16_values(const v1::PointArray& a) {
  std::vector<uint16_t> out(a.data().size() / 2);
  if (!out.empty()) std::memcpy(out.data(), a.data().data(), a.data().size());
  return out;
}

// binary16 from its definition: (−1)^s·2^(e−15)·(1 + f/1024), subnormals (−1)^s·2^-24·f.
double half_value(uint16_t h) {
  const int sign = (h & 0x8000) != 0 ? -1 : 1;
  const int e = (h >> 10) & 0x1F;
  const int f = h & 0x3FF;
  return e == 0 ? sign * std::ldexp(f, -24) : sign * std::ldexp(1024 + f, e - 25);
}

// Checks a 16-bit answer against the float32 answer for the same pose.
void expect_faithful(const v1::PointArray& reference, const v1::PointArray& compact, v1::PointEncoding encoding) {
  const uint32_t n = reference.point_count();
  const uint32_t d = reference.channel_count();
  ASSERT_EQ(compact.point_count(), n);
  ASSERT_EQ(compact.channel_count(), d);
  EXPECT_EQ(compact.encoding(), encoding);
  ASSERT_EQ(compact.data().size(), size_t{2} * n * d) << "2·N·D bytes";
  const std::vector<float> exact = float32_values(reference);
  const std::vector<uint16_t> q = uint16_values(compact);
  std::vector<double> bound(exact.size());
  std::vector<double> decoded(exact.size());
  if (encoding == v1::POINT_ENCODING_FLOAT16) {
    EXPECT_EQ(compact.scale_size(), 0);
    for (size_t i = 0; i < exact.size(); ++i) {
      decoded[i] = half_value(q[i]);
      bound[i] = std::max(std::ldexp(std::fabs(static_cast<double>(exact[i])), -11), std::ldexp(1.0, -25));
    }
  } else {
    ASSERT_EQ(compact.scale_size(), static_cast<int>(d));
    ASSERT_EQ(compact.offset_size(), static_cast<int>(d));
    for (uint32_t c = 0; c < d; ++c) {
      float lo = exact[c], hi = exact[c];
      for (uint32_t p = 0; p < n; ++p) {
        lo = std::min(lo, exact[size_t{p} * d + c]);
        hi = std::max(hi, exact[size_t{p} * d + c]);
      }
      EXPECT_EQ(compact.offset(static_cast<int>(c)), lo) << "offset = the channel's minimum";
      const double range = static_cast<double>(hi) - static_cast<double>(lo);
      EXPECT_GE(static_cast<double>(compact.scale(static_cast<int>(c))) * 65535.0, range);
      const double channel_bound =
          static_cast<double>(compact.scale(static_cast<int>(c))) / 2 +
          std::ldexp(range + std::max(std::fabs(static_cast<double>(lo)), std::fabs(static_cast<double>(hi))), -23);
      for (uint32_t p = 0; p < n; ++p) {
        const size_t i = size_t{p} * d + c;
        // value = offset + scale·q in float32, as the proto defines it.
        const float step = compact.scale(static_cast<int>(c)) * static_cast<float>(q[i]);
        decoded[i] = static_cast<double>(compact.offset(static_cast<int>(c)) + step);
        bound[i] = channel_bound;
      }
    }
  }
  double worst = 0.0;
  for (size_t i = 0; i < exact.size(); ++i) {
    const double error = std::fabs(decoded[i] - static_cast<double>(exact[i]));
    ASSERT_LE(error, static_cast<double>(compact.max_error())) << "value " << i;
    ASSERT_LE(error, bound[i]) << "value " << i;
    worst = std::max(worst, error);
  }
  EXPECT_GT(worst, 0.0) << "a lossy encoding of a posed mesh loses something";
  // max_error is the brute-force maximum, rounded up to float32 at most.
  EXPECT_LT(static_cast<double>(std::nextafter(compact.max_error(), 0.0f)), worst);
}

class PointEncodingTest : public testing::SmallRepositoryTest {
 protected:
  void SetUp() override {
    testing::SmallRepositoryTest::SetUp();
    server::ServerOptions options;
    options.miss_log_dir = work_.path();
    server_ = std::make_unique<InProcessServer>(repository(), options);
    poses_ = v1::PoseService::NewStub(server_->channel());
    auto stored = container::read_file(repository() / kPmsc / "1" / "model.anim");
    ASSERT_TRUE(stored.ok());
    auto model = pmsc::load(*stored, kPmsc);
    ASSERT_TRUE(model.ok()) << model.error().message;
    model_ = std::make_unique<pmsc::PmscModel>(std::move(*model));
    auto arm = container::read_file(repository() / std::string(demo::kDemoModelName) / "1" / "model.anim");
    ASSERT_TRUE(arm.ok());
    auto frames = arm->float_matrix(container::sections::kSequenceFrames);
    ASSERT_TRUE(frames.ok());
    // A training frame (a hit), and the same frame pushed off the subspace (a blend or miss).
    for (int f : {3, 7}) {
      Eigen::VectorXf full = frames->row(f).transpose();
      if (f == 7) {
        for (long i = 0; i < full.size(); i += 3) full(i + 1) += 0.05f * static_cast<float>(i % 7);
      }
      full_.push_back(full);
      keys_.push_back(pmsc::gather_key_values(*model_, full));
    }
  }

  v1::EvaluateKeyPointsRequest request(v1::PointEncoding encoding) const {
    v1::EvaluateKeyPointsRequest r;
    r.mutable_model()->set_name(kPmsc);
    r.set_points_encoding(encoding);
    for (const Eigen::VectorXf& keys : keys_) {
      *r.add_poses()->mutable_key_values() =
          float32_array(keys.data(), static_cast<uint32_t>(model_->key_point_count()), 3);
    }
    return r;
  }

  grpc::Status evaluate(const v1::EvaluateKeyPointsRequest& r, v1::EvaluateKeyPointsResponse& response) {
    grpc::ClientContext context;
    return poses_->EvaluateKeyPoints(&context, r, &response);
  }

  TempDir work_;
  std::unique_ptr<InProcessServer> server_;
  std::unique_ptr<v1::PoseService::Stub> poses_;
  std::unique_ptr<pmsc::PmscModel> model_;
  std::vector<Eigen::VectorXf> full_, keys_;
};

TEST_F(PointEncodingTest, EveryEncodingAnswersTheSameVerdictsWithinItsMaxError) {
  v1::EvaluateKeyPointsResponse reference;
  ASSERT_TRUE(evaluate(request(v1::POINT_ENCODING_UNSPECIFIED), reference).ok());
  ASSERT_EQ(reference.results_size(), 2);
  EXPECT_EQ(reference.results(0).status(), v1::CACHE_STATUS_HIT);
  EXPECT_NE(reference.results(1).status(), v1::CACHE_STATUS_HIT);
  for (v1::PointEncoding encoding :
       {v1::POINT_ENCODING_FLOAT32, v1::POINT_ENCODING_FLOAT16, v1::POINT_ENCODING_FIXED16}) {
    SCOPED_TRACE(v1::PointEncoding_Name(encoding));
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = evaluate(request(encoding), response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    ASSERT_EQ(response.results_size(), 2);
    for (int i = 0; i < 2; ++i) {
      const v1::PoseResult& a = reference.results(i);
      const v1::PoseResult& b = response.results(i);
      EXPECT_EQ(b.status(), a.status());
      EXPECT_EQ(b.key_point_error(), a.key_point_error());
      EXPECT_EQ(b.blend_weight(), a.blend_weight());
      EXPECT_EQ(b.full_evaluation_needed(), a.full_evaluation_needed());
      if (encoding == v1::POINT_ENCODING_FLOAT32) {
        EXPECT_EQ(b.points().data(), a.points().data());
        EXPECT_EQ(b.points().max_error(), 0.0f);
      } else {
        expect_faithful(a.points(), b.points(), encoding);
      }
    }
  }
}

TEST_F(PointEncodingTest, CompleteMissAnswersInTheRequestedEncoding) {
  const auto n = static_cast<uint32_t>(model_->point_count);
  const auto k = static_cast<uint32_t>(model_->key_point_count());
  v1::CompleteMissRequest complete;
  complete.mutable_model()->set_name(kPmsc);
  *complete.mutable_key_values() = float32_array(keys_[1].data(), k, 3);
  *complete.mutable_full_values() = float32_array(full_[1].data(), n, 3);
  v1::CompleteMissResponse reference;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(poses_->CompleteMiss(&context, complete, &reference).ok());
  }
  for (v1::PointEncoding encoding : {v1::POINT_ENCODING_FLOAT16, v1::POINT_ENCODING_FIXED16}) {
    SCOPED_TRACE(v1::PointEncoding_Name(encoding));
    complete.set_points_encoding(encoding);
    v1::CompleteMissResponse response;
    grpc::ClientContext context;
    const grpc::Status status = poses_->CompleteMiss(&context, complete, &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(response.result().status(), reference.result().status());
    expect_faithful(reference.result().points(), response.result().points(), encoding);
  }
  complete.set_points_encoding(static_cast<v1::PointEncoding>(9));
  v1::CompleteMissResponse response;
  grpc::ClientContext context;
  const grpc::Status status = poses_->CompleteMiss(&context, complete, &response);
  EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT);
  EXPECT_EQ(status.error_message().rfind("points_encoding: unknown PointEncoding 9", 0), 0u) << status.error_message();
}

TEST_F(PointEncodingTest, StreamFramesAnswerInTheirEncoding) {
  grpc::ClientContext context;
  auto stream = poses_->StreamKeyPoints(&context);
  const auto k = static_cast<uint32_t>(model_->key_point_count());
  const v1::PointEncoding encodings[] = {v1::POINT_ENCODING_FIXED16, v1::POINT_ENCODING_UNSPECIFIED,
                                         v1::POINT_ENCODING_FLOAT16};
  for (uint64_t s = 0; s < 3; ++s) {
    v1::KeyPointFrame frame;
    frame.mutable_model()->set_name(kPmsc);
    frame.set_sequence(s);
    frame.set_points_encoding(encodings[s]);
    *frame.mutable_pose()->mutable_key_values() = float32_array(keys_[0].data(), k, 3);
    ASSERT_TRUE(stream->Write(frame));
  }
  stream->WritesDone();
  v1::PoseResult result;
  for (uint64_t s = 0; s < 3; ++s) {
    ASSERT_TRUE(stream->Read(&result));
    EXPECT_EQ(result.sequence(), s);
    EXPECT_EQ(result.points().encoding(), encodings[s]);
    const size_t width = encodings[s] == v1::POINT_ENCODING_UNSPECIFIED ? 4 : 2;
    EXPECT_EQ(result.points().data().size(), width * static_cast<size_t>(model_->point_count) * 3);
  }
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(PointEncodingTest, KeyValuesIn16BitsReadAsTheValuesTheyDecodeTo) {
  const auto k = static_cast<uint32_t>(model_->key_point_count());
  // FIXED16 by hand: offset −2, step 2^-12 in every channel; the decoded values are exact in float32.
  v1::EvaluateKeyPointsRequest fixed;
  fixed.mutable_model()->set_name(kPmsc);
  v1::PointArray* keys = fixed.add_poses()->mutable_key_values();
  keys->set_point_count(k);
  keys->set_channel_count(3);
  keys->set_encoding(v1::POINT_ENCODING_FIXED16);
  std::vector<uint16_t> q(keys_[1].size());
  std::vector<float> decoded(q.size());
  for (size_t i = 0; i < q.size(); ++i) {
    const double steps = std::round((static_cast<double>(keys_[1](static_cast<Eigen::Index>(i))) + 2.0) * 4096.0);
    ASSERT_GE(steps, 0.0);
    ASSERT_LE(steps, 65535.0);
    q[i] = static_cast<uint16_t>(steps);
    decoded[i] = static_cast<float>(steps / 4096.0 - 2.0);
  }
  keys->set_data(q.data(), q.size() * 2);
  for (int c = 0; c < 3; ++c) {
    keys->add_scale(0x1p-12f);
    keys->add_offset(-2.0f);
  }
  v1::EvaluateKeyPointsRequest plain;
  plain.mutable_model()->set_name(kPmsc);
  *plain.add_poses()->mutable_key_values() = float32_array(decoded.data(), k, 3);
  v1::EvaluateKeyPointsResponse a, b;
  const grpc::Status status = evaluate(fixed, a);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_TRUE(evaluate(plain, b).ok());
  EXPECT_EQ(a.results(0).key_point_error(), b.results(0).key_point_error());
  EXPECT_EQ(a.results(0).points().data(), b.results(0).points().data());
}

TEST_F(PointEncodingTest, BadEncodingsAreRefusedNamingTheField) {
  struct Case {
    std::string name;
    void (*edit)(v1::EvaluateKeyPointsRequest&);
    std::string message;
  };
  const Case cases[] = {
      {"unknown answer encoding",
       [](v1::EvaluateKeyPointsRequest& r) { r.set_points_encoding(static_cast<v1::PointEncoding>(7)); },
       "points_encoding: unknown PointEncoding 7"},
      {"FIXED16 key values with one scale",
       [](v1::EvaluateKeyPointsRequest& r) {
         v1::PointArray* keys = r.mutable_poses(0)->mutable_key_values();
         keys->set_encoding(v1::POINT_ENCODING_FIXED16);
         keys->add_scale(1.0f);
       },
       "poses[0].key_values.scale: expected 3 values (one per channel) for FIXED16, got 1"},
      {"FLOAT16 key values with float32's length",
       [](v1::EvaluateKeyPointsRequest& r) {
         r.mutable_poses(0)->mutable_key_values()->set_encoding(v1::POINT_ENCODING_FLOAT16);
       },
       "poses[0].key_values.data: expected "},
      {"unknown key value encoding",
       [](v1::EvaluateKeyPointsRequest& r) {
         r.mutable_poses(0)->mutable_key_values()->set_encoding(static_cast<v1::PointEncoding>(5));
       },
       "poses[0].key_values.encoding: unknown PointEncoding 5"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    v1::EvaluateKeyPointsRequest r = request(v1::POINT_ENCODING_UNSPECIFIED);
    c.edit(r);
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = evaluate(r, response);
    EXPECT_EQ(status.error_code(), Code::INVALID_ARGUMENT) << status.error_message();
    EXPECT_EQ(status.error_message().rfind(c.message, 0), 0u) << status.error_message();
  }
  // The data length names both sizes and the encoding.
  v1::EvaluateKeyPointsRequest r = request(v1::POINT_ENCODING_UNSPECIFIED);
  r.mutable_poses(0)->mutable_key_values()->set_encoding(v1::POINT_ENCODING_FLOAT16);
  v1::EvaluateKeyPointsResponse response;
  const std::string k = std::to_string(model_->key_point_count());
  const std::string message = evaluate(r, response).error_message();
  EXPECT_EQ(message, "poses[0].key_values.data: expected " + std::to_string(6 * model_->key_point_count()) +
                         " bytes (2 · " + k + " · 3, FLOAT16), got " +
                         std::to_string(12 * model_->key_point_count()));
}

}  // namespace
}  // namespace animspace
