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
#include "core/animspace/import.h"
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

// A rig's character as a reader sees it: written as .glb and parsed back with tinygltf.
testing::LoadedGltf exported_glb(const LinearBlendModel& rig, const std::vector<TransformList>& poses) {
  testing::LoadedGltf failed;
  auto character = skinned_character(rig, poses, kFps);
  if (!character) {
    failed.error = character.error().message;
    return failed;
  }
  const auto bytes = mesh_io::serialize_skinned_glb(*character);
  if (!bytes) {
    failed.error = bytes.error().message;
    return failed;
  }
  return testing::load_gltf(*bytes, /*binary=*/true);
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
  const testing::LoadedGltf loaded = exported_glb(*lbs_, poses);
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

// An animation-space model imported from a linear blend rig (p_j = w_j Ĝ_j⁻¹ v̂, §3.1 — what
// import-rig makes) exports as that very rig: the same weights and bind pose, and the file posed
// from the glTF alone is the animation-space model in every pose (issue #39: import-rig and
// build-lod models could not be exported as a rig).
TEST_F(RigExportTest, AModelImportedFromARigExportsAsThatRig) {
  const AnimationSpaceModel imported = from_linear_blend(*lbs_);
  auto converted = linear_blend_rig(imported);
  ASSERT_TRUE(converted) << converted.error().message;
  EXPECT_EQ(converted->negative_weights_dropped, 0);
  const LinearBlendModel* rig = &converted->model;
  ASSERT_EQ(rig->vertex_count(), lbs_->vertex_count());
  EXPECT_LE(max_distance(rig->rest_points.transpose(), lbs_->rest_points.transpose()), 1e-9 * kLength);
  for (int i = 0; i < lbs_->vertex_count(); ++i) {
    // The imported influences are the rig's less its exact-zero weights, in the same order.
    std::vector<std::pair<int, double>> expected, got;
    for (int k = lbs_->influences.begin(i); k < lbs_->influences.end(i); ++k) {
      if (lbs_->weights(k) != 0) expected.emplace_back(lbs_->influences.bones[static_cast<size_t>(k)], lbs_->weights(k));
    }
    for (int k = rig->influences.begin(i); k < rig->influences.end(i); ++k) {
      got.emplace_back(rig->influences.bones[static_cast<size_t>(k)], rig->weights(k));
    }
    ASSERT_EQ(got.size(), expected.size()) << "vertex " << i;
    for (size_t k = 0; k < got.size(); ++k) {
      EXPECT_EQ(got[k].first, expected[k].first) << "vertex " << i;
      EXPECT_NEAR(got[k].second, expected[k].second, 1e-12) << "vertex " << i;
    }
  }
  const testing::LoadedGltf loaded = exported_glb(*rig, skeleton_->training_poses);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Animation* animation = testing::only_animation(loaded.model);
  ASSERT_NE(animation, nullptr);
  const std::vector<float> times = testing::keyframe_times(loaded.model, *animation);
  PointMatrix evaluated;
  for (size_t k = 0; k < times.size(); ++k) {
    const Eigen::MatrixX3d posed = testing::skin_from_file(
        loaded.model, testing::node_globals(loaded.model, animation, times[k], Rotations::kSpecSlerp));
    evaluate(imported, skeleton_->training_poses[k], evaluated);
    EXPECT_LE(max_distance(posed, to_double(evaluated)), 1e-5 * kLength) << "frame " << k;
  }
}

// A model with what linear blend skinning cannot express (a p_j not along Ĝ_j⁻¹ v̂): its rig keeps
// the weights and the rest pose — equal to the model at rest. A negative weight, which no glTF
// skin holds, is dropped and counted; a vertex with no positive weight is refused.
TEST_F(RigExportTest, AModelBeyondLinearBlendKeepsItsRestPoseAndNegativeWeightsAreDroppedAndCounted) {
  AnimationSpaceModel model = from_linear_blend(*lbs_);
  const int vertex = model.vertex_count() / 2;
  const int first = model.influences.begin(vertex);
  model.positions.col(first).head<3>() += Eigen::Vector3d(0.3, -0.2, 0.1);  // weight unchanged
  auto converted = linear_blend_rig(model);
  ASSERT_TRUE(converted) << converted.error().message;
  const LinearBlendModel* rig = &converted->model;
  PointMatrix at_rest;
  evaluate(model, model.skeleton.rest, at_rest);
  EXPECT_LE(max_distance(rig->rest_points.transpose(), to_double(at_rest)), 1e-6 * kLength);  // evaluate is float32

  AnimationSpaceModel negative = from_linear_blend(*lbs_);
  int v = 0;
  while (v < negative.vertex_count() && negative.influences.end(v) - negative.influences.begin(v) < 2) ++v;
  ASSERT_LT(v, negative.vertex_count()) << "a vertex with two influences";
  const int k0 = negative.influences.begin(v);
  // Move weight between two influences so that one goes below 0 and the sum stays 1.
  const double shift = negative.positions(3, k0) + 0.25;
  negative.positions.col(k0) *= (negative.positions(3, k0) - shift) / negative.positions(3, k0);
  negative.positions.col(k0 + 1) *= (negative.positions(3, k0 + 1) + shift) / negative.positions(3, k0 + 1);
  const double dropped = negative.positions(3, k0);
  auto kept = linear_blend_rig(negative);
  ASSERT_TRUE(kept) << kept.error().message;
  EXPECT_EQ(kept->negative_weights_dropped, 1);
  EXPECT_DOUBLE_EQ(kept->most_negative_weight, dropped);
  // The vertex keeps its other weights, rescaled to sum to 1, so the rig is still exact at rest.
  double sum = 0;
  for (int k = kept->model.influences.begin(v); k < kept->model.influences.end(v); ++k) {
    EXPECT_NE(kept->model.influences.bones[static_cast<size_t>(k)], negative.influences.bones[static_cast<size_t>(k0)]);
    EXPECT_GT(kept->model.weights(k), 0);
    sum += kept->model.weights(k);
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  PointMatrix model_rest, rig_rest;
  evaluate(negative, negative.skeleton.rest, model_rest);
  evaluate(kept->model, negative.skeleton.rest, rig_rest);
  EXPECT_LE(max_distance(to_double(rig_rest), to_double(model_rest)), 1e-6 * kLength);  // float32 evaluation
  // A vertex without any positive weight cannot be skinned at all: refused, naming it.
  AnimationSpaceModel none = from_linear_blend(*lbs_);
  for (int k = none.influences.begin(v); k < none.influences.end(v); ++k) none.positions(3, k) = 0;
  none.positions(3, none.influences.begin(v)) = -1;
  none.positions(3, none.influences.begin(v) + 1) = 2;
  none.positions(3, none.influences.begin(v) + 1) *= -1;  // −2: every weight ≤ 0
  auto refused = linear_blend_rig(none);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kFailedPrecondition);
  EXPECT_NE(refused.error().message.find("vertex " + std::to_string(v) + ":"), std::string::npos)
      << refused.error().message;
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
