// The request validation layer, in process: each refusal names the field, the expected and the
// actual value; accepted input decodes bit for bit.
#include "server/validation.h"

#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "core/animspace/skeleton.h"

namespace animspace::server {
namespace {

v1::PointArray array_of(const std::vector<float>& values, uint32_t points, uint32_t channels) {
  v1::PointArray out;
  out.set_point_count(points);
  out.set_channel_count(channels);
  out.set_data(values.data(), values.size() * sizeof(float));
  return out;
}

void expect_refusal(const grpc::Status& status, grpc::StatusCode code, const std::string& message) {
  EXPECT_EQ(status.error_code(), code) << status.error_message();
  EXPECT_EQ(status.error_message(), message);
}

TEST(Validation, DecodesAWellFormedArrayExactly) {
  const std::vector<float> values{1.5f, -2.0f, 3.25f, 0.0f, 1e-30f, -7.0f};
  Eigen::VectorXf out;
  ASSERT_TRUE(decode_points(array_of(values, 2, 3), "key_values", 2, 3, "key points", out).ok());
  ASSERT_EQ(out.size(), 6);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(out[i], values[static_cast<size_t>(i)]);
}

TEST(Validation, NamesTheFieldWithExpectedAndActual) {
  Eigen::VectorXf out;
  const std::vector<float> six(6, 1.0f);
  expect_refusal(decode_points(array_of(six, 2, 3), "poses[4].key_values", 3, 3, "key points", out),
                 grpc::StatusCode::INVALID_ARGUMENT, "poses[4].key_values.point_count: expected 3 key points, got 2");
  expect_refusal(decode_points(array_of(six, 3, 2), "f", 3, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.channel_count: expected 3, got 2");
  expect_refusal(decode_points(array_of(six, 3, 3), "f", 3, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.data: expected 36 bytes (4 · 3 · 3), got 24");
  std::vector<float> bad(9, 0.0f);
  bad[7] = std::numeric_limits<float>::quiet_NaN();
  expect_refusal(decode_points(array_of(bad, 3, 3), "f", 3, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.data: value of point 2, channel 1 is NaN; expected finite values");
  bad[7] = 0;
  bad[3] = -std::numeric_limits<float>::infinity();
  expect_refusal(decode_points(array_of(bad, 3, 3), "f", 3, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.data: value of point 1, channel 0 is infinite; expected finite values");
}

v1::PointArray halves_of(const std::vector<uint16_t>& halves, uint32_t points, uint32_t channels) {
  v1::PointArray out;
  out.set_point_count(points);
  out.set_channel_count(channels);
  out.set_encoding(v1::POINT_ENCODING_FLOAT16);
  out.set_data(halves.data(), halves.size() * 2);
  return out;
}

TEST(Validation, Decodes16BitArraysByHand) {
  Eigen::VectorXf out;
  // binary16 by hand: 0x3C00 = 1, 0xC000 = −2, 0x0001 = 2^-24, 0x7BFF = 65504,
  // 0x3555 = 2^(13−15)·(1 + 0x155/1024) = (1 + 341/1024)/4.
  ASSERT_TRUE(decode_points(halves_of({0x3C00, 0xC000, 0x0001, 0x7BFF, 0x3555, 0x0000}, 2, 3), "f", 2, 3, "points", out)
                  .ok());
  const std::vector<float> expected = {1.0f, -2.0f, 0x1p-24f, 65504.0f, (1.0f + 341.0f / 1024.0f) / 4.0f, 0.0f};
  for (int i = 0; i < 6; ++i) EXPECT_EQ(out[i], expected[static_cast<size_t>(i)]) << i;
  // FIXED16: value = offset[c] + scale[c]·q.
  v1::PointArray fixed = halves_of({0, 1, 2, 3, 4, 5}, 2, 3);
  fixed.set_encoding(v1::POINT_ENCODING_FIXED16);
  for (float v : {0.5f, 2.0f, 0.0f}) fixed.add_scale(v);
  for (float v : {1.0f, -3.0f, 7.0f}) fixed.add_offset(v);
  ASSERT_TRUE(decode_points(fixed, "f", 2, 3, "points", out).ok());
  const std::vector<float> fixed_expected = {1.0f, -1.0f, 7.0f, 2.5f, 5.0f, 7.0f};
  for (int i = 0; i < 6; ++i) EXPECT_EQ(out[i], fixed_expected[static_cast<size_t>(i)]) << i;
}

TEST(Validation, Bad16BitArraysAreRefusedNamingTheMember) {
  Eigen::VectorXf out;
  const v1::PointArray good = halves_of({0x3C00, 0x3C00, 0x3C00, 0x3C00, 0x3C00, 0x3C00}, 2, 3);
  v1::PointArray a = good;
  a.set_data(std::string(24, '\0'));  // float32's length for a FLOAT16 array
  expect_refusal(decode_points(a, "poses[0].key_values", 2, 3, "key points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].key_values.data: expected 12 bytes (2 · 2 · 3, FLOAT16), got 24");
  a = good;
  a.set_encoding(static_cast<v1::PointEncoding>(9));
  expect_refusal(decode_points(a, "poses[0].key_values", 2, 3, "key points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].key_values.encoding: unknown PointEncoding 9; expected POINT_ENCODING_FLOAT32 (or unset), "
                 "POINT_ENCODING_FLOAT16, POINT_ENCODING_FIXED16 or POINT_ENCODING_COORDINATES");
  a = good;
  a.set_encoding(v1::POINT_ENCODING_COORDINATES);
  expect_refusal(decode_points(a, "poses[0].key_values", 2, 3, "key points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].key_values.encoding: POINT_ENCODING_COORDINATES is for answers only; send FLOAT32, "
                 "FLOAT16 or FIXED16 values");
  a = good;
  a.set_encoding(v1::POINT_ENCODING_FIXED16);
  a.add_scale(1.0f);
  for (int c = 0; c < 3; ++c) a.add_offset(0.0f);
  expect_refusal(decode_points(a, "poses[0].key_values", 2, 3, "key points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].key_values.scale: expected 3 values (one per channel) for FIXED16, got 1");
  a.add_scale(1.0f);
  a.add_scale(1.0f);
  a.set_offset(1, std::numeric_limits<float>::quiet_NaN());
  expect_refusal(decode_points(a, "f", 2, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.offset[1]: NaN; expected a finite value");
  a.set_offset(1, 0.0f);
  a.set_scale(2, std::numeric_limits<float>::infinity());
  expect_refusal(decode_points(a, "f", 2, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.scale[2]: infinite; expected a finite value");
  // Finite parameters whose values overflow float32 are refused like an infinite value.
  a.set_scale(2, 3e38f);
  a.set_offset(2, 3e38f);
  expect_refusal(decode_points(a, "f", 2, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.data: value of point 0, channel 2 is infinite; expected finite values");
  // scale on a float32 array: the encoding was forgotten.
  v1::PointArray plain = array_of(std::vector<float>(6, 1.0f), 2, 3);
  plain.add_scale(1.0f);
  expect_refusal(decode_points(plain, "f", 2, 3, "points", out), grpc::StatusCode::INVALID_ARGUMENT,
                 "f.scale: only FIXED16 arrays carry one; this one is float32 (encoding unset) "
                 "(set encoding = POINT_ENCODING_FIXED16?)");
  // A float16 Inf pattern.
  expect_refusal(decode_points(halves_of({0x3C00, 0x7C00, 0, 0, 0, 0}, 2, 3), "f", 2, 3, "points", out),
                 grpc::StatusCode::INVALID_ARGUMENT, "f.data: value of point 0, channel 1 is infinite; expected finite values");
}

TEST(Validation, EncodingRefusesWhatFloat16CannotCarry) {
  const std::vector<float> values = {1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 1e5f};
  v1::PointArray out;
  expect_refusal(encode_points(values.data(), 2, 3, v1::POINT_ENCODING_FLOAT16, &out), grpc::StatusCode::OUT_OF_RANGE,
                 "points_encoding: FLOAT16 cannot carry this answer: value of point 1, channel 2 is 1e+05, beyond "
                 "±65504, the largest float16; ask for POINT_ENCODING_FIXED16 or FLOAT32");
  EXPECT_EQ(out.data().size(), 0u);
  // FIXED16 carries it, within half a step of its channel.
  ASSERT_TRUE(encode_points(values.data(), 2, 3, v1::POINT_ENCODING_FIXED16, &out).ok());
  EXPECT_EQ(out.data().size(), 12u);
  EXPECT_LE(out.max_error(), (1e5f - 3.0f) / 65535.0f);
  expect_refusal(check_points_encoding(static_cast<v1::PointEncoding>(7), "points_encoding"),
                 grpc::StatusCode::INVALID_ARGUMENT,
                 "points_encoding: unknown PointEncoding 7; expected POINT_ENCODING_FLOAT32 (or unset), "
                 "POINT_ENCODING_FLOAT16, POINT_ENCODING_FIXED16 or POINT_ENCODING_COORDINATES");
}

TEST(Validation, ABogusPointCountNeverAllocates) {
  // 4 billion points claimed with 12 bytes of data: refused by the count check, before any
  // allocation could follow the claim.
  Eigen::VectorXf out;
  v1::PointArray claim = array_of({1, 2, 3}, 4000000000u, 3);
  const auto status = decode_points(claim, "f", 1, 3, "points", out);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(out.size(), 0);
}

TEST(Validation, BatchAndResponseSizes) {
  EXPECT_TRUE(check_batch_size(1, 8, "poses").ok());
  EXPECT_TRUE(check_batch_size(8, 8, "poses").ok());
  expect_refusal(check_batch_size(0, 8, "poses"), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses: empty batch, expected 1..8 entries");
  expect_refusal(check_batch_size(9, 8, "poses"), grpc::StatusCode::RESOURCE_EXHAUSTED,
                 "poses: 9 entries, the limit is 8 (--max-batch-poses); split the batch");
  // 10 entries of 936 bytes (+64 allowance each) = 10,000 bytes: exactly at a 10,000-byte limit.
  EXPECT_TRUE(check_response_size(10, 936, 10000, "poses").ok());
  EXPECT_EQ(check_response_size(10, 937, 10000, "poses").error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
}

TEST(Validation, SkeletonPosesComposeLocalTransformsDownTheHierarchy) {
  // Two bones: root and a child. Local pose: root translated by (1, 0, 0), child rotated 90°
  // about z and translated by (0, 2, 0) relative to it. G_1 = L_0 · L_1 by hand.
  animation_space::Skeleton skeleton;
  skeleton.parents = {-1, 0};
  skeleton.rest = {animation_space::Transform::Identity(), animation_space::Transform::Identity()};
  animation_space::Transform L0 = animation_space::Transform::Identity();
  L0(0, 3) = 1;
  animation_space::Transform L1 = animation_space::Transform::Identity();
  L1.block<2, 2>(0, 0) << 0, -1, 1, 0;
  L1(1, 3) = 2;
  v1::SkeletonPose pose;
  pose.set_space(v1::SkeletonPose::SPACE_LOCAL);
  pose.set_bone_count(2);
  std::string bytes;
  for (const auto* L : {&L0, &L1}) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        const float v = static_cast<float>((*L)(r, c));
        bytes.append(reinterpret_cast<const char*>(&v), sizeof v);
      }
    }
  }
  pose.set_transforms(bytes);
  animation_space::TransformList globals;
  ASSERT_TRUE(decode_skeleton_pose(pose, "pose", skeleton, globals).ok());
  ASSERT_EQ(globals.size(), 2u);
  animation_space::Transform expected = animation_space::Transform::Identity();
  expected.block<2, 2>(0, 0) << 0, -1, 1, 0;
  expected(0, 3) = 1;
  expected(1, 3) = 2;
  EXPECT_LT((globals[1] - expected).cwiseAbs().maxCoeff(), 1e-12);

  pose.set_bone_count(3);
  expect_refusal(decode_skeleton_pose(pose, "poses[0]", skeleton, globals), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].bone_count: expected 2, got 3");
  pose.set_bone_count(2);
  pose.set_transforms(bytes.substr(0, 40));
  expect_refusal(decode_skeleton_pose(pose, "poses[0]", skeleton, globals), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].transforms: expected 96 bytes (4 · 12 · 2 bones), got 40");
  std::string nan_bytes = bytes;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(nan_bytes.data() + (12 + 5) * sizeof(float), &nan, sizeof nan);
  pose.set_transforms(nan_bytes);
  expect_refusal(decode_skeleton_pose(pose, "poses[0]", skeleton, globals), grpc::StatusCode::INVALID_ARGUMENT,
                 "poses[0].transforms: bone 1, entry (1,1) is NaN; expected finite values");
}

}  // namespace
}  // namespace animspace::server
