// A fitted linear blend rig exported as glTF: the .glb, posed from the file alone (tinygltf and
// the specification's formulas, tests/support/gltf_posing.h), is the model in every training pose
// and so reproduces the captured frames as closely as the model itself does.
#include "core/animspace/rig_export.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "core/animspace/fit_sequence.h"
#include "core/animspace/model.h"
#include "core/mesh_io/gltf_skin_writer.h"
#include "tests/support/articulated_tube.h"
#include "tests/support/gltf_posing.h"

namespace animspace::animation_space {
namespace {

using testing::make_tube;
using testing::max_distance;
using testing::Rotations;

constexpr int kSegments = 3, kRingsPerSegment = 8, kFrames = 12;
constexpr double kFps = 30;
constexpr double kLength = kSegments * kRingsPerSegment * testing::ArticulatedTube::kRingSpacing;

// One fit of a smoothly skinned tube (blended across each joint over ±3 rings), shared by the
// tests: the pipeline `animspace fit --export` runs, phases 1–3 and the linear blend model.
class RigExportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    tube_ = new testing::ArticulatedTube(make_tube(kSegments, kRingsPerSegment, kFrames, 51, 3.0));
    TriangleMesh reference;
    reference.V = tube_->rest;
    reference.F = tube_->faces;
    SequenceFitOptions options;
    options.segmentation.bone_count = kSegments;
    auto skeleton = fit_sequence_skeleton(reference, tube_->frames, options, nullptr);
    ASSERT_TRUE(skeleton) << skeleton.error().message;
    auto lbs = fit_sequence_linear_blend(reference, tube_->frames, *skeleton, options.fit, nullptr);
    ASSERT_TRUE(lbs) << lbs.error().message;
    skeleton_ = new SequenceSkeleton(std::move(*skeleton));
    lbs_ = new LinearBlendModel(std::move(*lbs));
  }
  static void TearDownTestSuite() {
    delete lbs_;
    delete skeleton_;
    delete tube_;
  }
  void SetUp() override {
    if (lbs_ == nullptr) GTEST_SKIP() << "the fit failed (reported by SetUpTestSuite)";
  }

  static testing::ArticulatedTube* tube_;
  static SequenceSkeleton* skeleton_;
  static LinearBlendModel* lbs_;
};

testing::ArticulatedTube* RigExportTest::tube_ = nullptr;
SequenceSkeleton* RigExportTest::skeleton_ = nullptr;
LinearBlendModel* RigExportTest::lbs_ = nullptr;

Eigen::MatrixX3d to_double(const PointMatrix& points) { return points.cast<double>(); }

Eigen::MatrixX3d captured_frame(const FrameMatrix& frames, Eigen::Index k) {
  const Eigen::Map<const PointMatrix> points(frames.row(k).data(), frames.cols() / 3, 3);
  return points.cast<double>();
}

TEST_F(RigExportTest, TheGlbPosedFromTheFileIsTheModelInEveryTrainingPose) {
  const std::vector<TransformList>& poses = skeleton_->training_poses;
  ASSERT_EQ(poses.size(), static_cast<size_t>(kFrames));
  auto character = skinned_character(*lbs_, poses, kFps);
  ASSERT_TRUE(character) << character.error().message;
  const auto bytes = mesh_io::serialize_skinned_glb(*character);
  ASSERT_TRUE(bytes) << bytes.error().message;
  const testing::LoadedGltf loaded = testing::load_gltf(*bytes, /*binary=*/true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Model& gltf = loaded.model;

  // One joint per bone (the root included), one vertex per vertex of the mesh.
  ASSERT_EQ(gltf.skins.size(), 1u);
  EXPECT_EQ(gltf.skins[0].joints.size(), static_cast<size_t>(lbs_->skeleton.bone_count()));
  EXPECT_EQ(lbs_->skeleton.bone_count(), kSegments + 1);

  // Without its animation the file is the bind pose: the model's rest points.
  const double tolerance = 1e-5 * kLength;
  const Eigen::MatrixX3d bind =
      testing::skin_from_file(gltf, testing::node_globals(gltf, nullptr, 0, Rotations::kSpecSlerp));
  EXPECT_LE(max_distance(bind, lbs_->rest_points.transpose()), tolerance);

  // Keyframe k at k / fps, posed from the file, is the model evaluated in training pose k.
  const tinygltf::Animation* animation = testing::only_animation(gltf);
  ASSERT_NE(animation, nullptr);
  const std::vector<float> times = testing::keyframe_times(gltf, *animation);
  ASSERT_EQ(times.size(), poses.size());
  PointMatrix evaluated;
  for (size_t k = 0; k < times.size(); ++k) {
    EXPECT_NEAR(times[k], static_cast<double>(k) / kFps, 1e-6) << "frame " << k;
    const Eigen::MatrixX3d posed =
        testing::skin_from_file(gltf, testing::node_globals(gltf, animation, times[k], Rotations::kSpecSlerp));
    evaluate(*lbs_, poses[k], evaluated);
    EXPECT_LE(max_distance(posed, to_double(evaluated)), tolerance) << "frame " << k;
  }
}

// The captured frames themselves: the file reproduces each one as closely as the model does (its
// own fit error, measured here point by point), and the model fits the smooth tube closely, so
// the exported animation is the sequence.
TEST_F(RigExportTest, TheGlbReproducesTheFittedFramesToTheModelsOwnError) {
  const std::vector<TransformList>& poses = skeleton_->training_poses;
  auto character = skinned_character(*lbs_, poses, kFps);
  ASSERT_TRUE(character) << character.error().message;
  const auto bytes = mesh_io::serialize_skinned_glb(*character);
  ASSERT_TRUE(bytes) << bytes.error().message;
  const testing::LoadedGltf loaded = testing::load_gltf(*bytes, /*binary=*/true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Animation* animation = testing::only_animation(loaded.model);
  ASSERT_NE(animation, nullptr);
  const std::vector<float> times = testing::keyframe_times(loaded.model, *animation);
  ASSERT_EQ(times.size(), static_cast<size_t>(tube_->frames.rows()));

  const double tolerance = 1e-5 * kLength;
  double model_squared = 0, file_squared = 0, model_max = 0, file_max = 0;
  Eigen::Index count = 0;
  PointMatrix evaluated;
  for (size_t k = 0; k < times.size(); ++k) {
    const Eigen::MatrixX3d captured = captured_frame(tube_->frames, static_cast<Eigen::Index>(k));
    evaluate(*lbs_, poses[k], evaluated);
    const Eigen::MatrixX3d posed = testing::skin_from_file(
        loaded.model, testing::node_globals(loaded.model, animation, times[k], Rotations::kSpecSlerp));
    ASSERT_EQ(posed.rows(), captured.rows());
    const Eigen::VectorXd model_distances = (to_double(evaluated) - captured).rowwise().norm();
    const Eigen::VectorXd file_distances = (posed - captured).rowwise().norm();
    model_squared += model_distances.squaredNorm();
    file_squared += file_distances.squaredNorm();
    model_max = std::max(model_max, model_distances.maxCoeff());
    file_max = std::max(file_max, file_distances.maxCoeff());
    count += captured.rows();
  }
  const double model_rms = std::sqrt(model_squared / static_cast<double>(count));
  const double file_rms = std::sqrt(file_squared / static_cast<double>(count));
  EXPECT_LE(file_rms, model_rms + tolerance);
  EXPECT_LE(file_max, model_max + tolerance);
  // A fit that missed the tube would make the comparison above hollow.
  EXPECT_LT(model_rms, 5e-4 * kLength);
}

TEST_F(RigExportTest, APoseWithTheWrongBoneCountIsRejectedNamingIt) {
  std::vector<TransformList> poses = skeleton_->training_poses;
  poses[2].pop_back();
  const auto fewer = skinned_character(*lbs_, poses, kFps);
  ASSERT_FALSE(fewer);
  EXPECT_EQ(fewer.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(fewer.error().message.find("poses[2]"), std::string::npos) << fewer.error().message;

  poses = skeleton_->training_poses;
  poses[5].push_back(Transform::Identity());
  const auto more = skinned_character(*lbs_, poses, kFps);
  ASSERT_FALSE(more);
  EXPECT_EQ(more.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(more.error().message.find("poses[5]"), std::string::npos) << more.error().message;
}

}  // namespace
}  // namespace animspace::animation_space
