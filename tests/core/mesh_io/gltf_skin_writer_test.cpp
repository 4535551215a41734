#include "core/mesh_io/gltf_skin_writer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/common/atomic_file.h"
#include "core/mesh_io/gltf_skin.h"
#include "tests/support/gltf_posing.h"
#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::accessor_values;
using animspace::testing::keyframe_times;
using animspace::testing::load_gltf;
using animspace::testing::LoadedGltf;
using animspace::testing::max_distance;
using animspace::testing::morph_weights_at;
using animspace::testing::node_globals;
using animspace::testing::only_animation;
using animspace::testing::Rotations;
using animspace::testing::skin_from_file;
using animspace::testing::TempDir;

constexpr double kDegree = std::numbers::pi / 180;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Eigen::Matrix3d rotation(const Eigen::Vector3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

Eigen::Matrix4d rigid(const Eigen::Matrix3d& r, const Eigen::Vector3d& t) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = r;
  m.topRightCorner<3, 1>() = t;
  return m;
}

// --- The test character, built by hand -------------------------------------------------------
//
// Seven joints in two trees: hips(0) → spine(1) → neck(2) → head(3), spine(1) → arm(4) → hand(5),
// and a second root prop(6). Each joint's local transform at (possibly fractional) frame k is
// rigid(B_j · Rot(a_j, ω_j k), o_j + d_j k): a bind rotation and offset, a steady turn about its
// own axis and (for the roots) a steady drift. The neck turns 50° a frame and the prop 70° (300°
// and 420° over the sequence), so consecutive quaternions cross the 180° where a sign must flip.
struct JointSpec {
  int32_t parent;
  const char* name;
  Eigen::Vector3d bind_axis;
  double bind_angle;
  Eigen::Vector3d offset;
  Eigen::Vector3d turn_axis;
  double turn_per_frame;
  Eigen::Vector3d drift_per_frame;
};

std::vector<JointSpec> joint_specs() {
  using V = Eigen::Vector3d;
  return {
      {-1, "hips", V(0, 0, 1), 17 * kDegree, V(0.1, -0.2, 0.05), V(0, 0, 1), 10 * kDegree, V(0.1, 0, 0.05)},
      {0, "spine", V(0, 1, 0), -25 * kDegree, V(1.0, 0.1, 0), V(1, 0, 0), -20 * kDegree, V::Zero()},
      {1, "neck", V(1, 1, 0), 30 * kDegree, V(1.0, 0.3, 0), V(0, 1, 0), 50 * kDegree, V::Zero()},
      {2, "head", V(0, 0, 1), 5 * kDegree, V(0.6, 0, 0), V(1, -2, 3), 15 * kDegree, V::Zero()},
      {1, "arm", V(1, 0, 0), 90 * kDegree, V(0.5, 0, 0.4), V(1, 1, 0), 35 * kDegree, V::Zero()},
      {4, "hand", V(0, 1, 1), -40 * kDegree, V(0.7, 0, 0), V(0, 0, 1), -25 * kDegree, V::Zero()},
      {-1, "prop", V(1, 2, 2), 120 * kDegree, V(2.0, 1.0, -0.5), V(1, 0, 0), 70 * kDegree, V(0, -0.05, 0.02)},
  };
}

constexpr int kFrames = 7;
constexpr double kFps = 30;

// Global transforms at frame k (fractional k: the continuous motion the frames sample).
Matrix4dList globals_at(const std::vector<JointSpec>& specs, double k, double scale, bool animated) {
  Matrix4dList globals;
  for (const JointSpec& s : specs) {
    const double turn = animated ? s.turn_per_frame * k : 0;
    const Eigen::Vector3d drift = animated ? Eigen::Vector3d(s.drift_per_frame * k) : Eigen::Vector3d::Zero();
    const Eigen::Matrix4d local =
        rigid(rotation(s.bind_axis, s.bind_angle) * rotation(s.turn_axis, turn), scale * (s.offset + drift));
    globals.push_back(s.parent < 0 ? local : Eigen::Matrix4d(globals[static_cast<size_t>(s.parent)] * local));
  }
  return globals;
}

constexpr int kRings = 8, kSides = 6;

// A bent open tube of kRings × kSides vertices around y = 0.2 x², faces wound outwards, every
// vertex influenced by 2 … 6 distinct joints (so JOINTS_1 / WEIGHTS_1 are needed), one influence
// with weight 0.
SkinnedCharacter make_character(double scale) {
  const std::vector<JointSpec> specs = joint_specs();
  SkinnedCharacter c;
  c.bind_points.resize(kRings * kSides, 3);
  for (int r = 0; r < kRings; ++r) {
    const double x = 3.5 * r / (kRings - 1);
    for (int s = 0; s < kSides; ++s) {
      const double theta = 2 * std::numbers::pi * s / kSides;
      c.bind_points.row(r * kSides + s) =
          scale * Eigen::RowVector3d(x, 0.2 * x * x + 0.3 * std::cos(theta), 0.3 * std::sin(theta));
    }
  }
  c.faces.resize(2 * (kRings - 1) * kSides, 3);
  for (int r = 0; r + 1 < kRings; ++r) {
    for (int s = 0; s < kSides; ++s) {
      const int a = r * kSides + s, b = (r + 1) * kSides + s, cc = (r + 1) * kSides + (s + 1) % kSides,
                d = r * kSides + (s + 1) % kSides;
      const int f = 2 * (r * kSides + s);
      c.faces.row(f) << a, cc, b;
      c.faces.row(f + 1) << a, d, cc;
    }
  }
  for (const JointSpec& s : specs) {
    c.joint_parents.push_back(s.parent);
    c.joint_names.emplace_back(s.name);
  }
  c.bind_globals = globals_at(specs, 0, scale, /*animated=*/false);

  std::mt19937 random(7);
  std::uniform_real_distribution<double> weight(0.1, 1.0);
  c.offsets.push_back(0);
  for (int v = 0; v < c.bind_points.rows(); ++v) {
    std::vector<int32_t> order = {0, 1, 2, 3, 4, 5, 6};
    std::shuffle(order.begin(), order.end(), random);
    const int count = 2 + v % 5;
    std::vector<double> w(static_cast<size_t>(count));
    for (double& x : w) x = weight(random);
    if (v == 9) w[4] = 0;  // an explicit zero weight (vertex 9 has 6 influences)
    double sum = 0;
    for (const double x : w) sum += x;
    for (int i = 0; i < count; ++i) {
      c.joints.push_back(order[static_cast<size_t>(i)]);
      c.weights.push_back(w[static_cast<size_t>(i)] / sum);
    }
    c.offsets.push_back(static_cast<int32_t>(c.joints.size()));
  }
  for (int k = 0; k < kFrames; ++k) c.frame_globals.push_back(globals_at(specs, k, scale, /*animated=*/true));
  c.frames_per_second = kFps;
  c.animation_name = "wave";
  return c;
}

// Σ_i w_i G_{j_i} B_{j_i}⁻¹ v̂: linear blend skinning straight from the character and the
// globals (B⁻¹ by Eigen's general inverse, not the writer's rigid one).
Eigen::MatrixX3d skin_directly(const SkinnedCharacter& c, const Matrix4dList& globals) {
  Eigen::MatrixX3d out(c.bind_points.rows(), 3);
  for (Eigen::Index v = 0; v < c.bind_points.rows(); ++v) {
    const Eigen::Vector4d rest(c.bind_points(v, 0), c.bind_points(v, 1), c.bind_points(v, 2), 1);
    Eigen::Vector4d posed = Eigen::Vector4d::Zero();
    for (int32_t i = c.offsets[static_cast<size_t>(v)]; i < c.offsets[static_cast<size_t>(v) + 1]; ++i) {
      const size_t j = static_cast<size_t>(c.joints[static_cast<size_t>(i)]);
      posed += c.weights[static_cast<size_t>(i)] * (globals[j] * c.bind_globals[j].inverse() * rest);
    }
    out.row(v) = posed.head<3>().transpose();
  }
  return out;
}

double size_of(const SkinnedCharacter& c) {
  return (c.bind_points.colwise().maxCoeff() - c.bind_points.colwise().minCoeff()).norm();
}

// Every keyframe, posed from the file at the time it stores for that frame, against linear blend
// skinning computed here from the character; and the file without its animation is the bind pose.
void expect_poses_every_frame(const tinygltf::Model& model, const SkinnedCharacter& c, const std::string& what) {
  const double tolerance = 1e-5 * size_of(c);
  const Eigen::MatrixX3d bind = skin_from_file(model, node_globals(model, nullptr, 0, Rotations::kSpecSlerp));
  EXPECT_LE(max_distance(bind, c.bind_points), tolerance) << what << ": bind pose";
  const tinygltf::Animation* animation = only_animation(model);
  ASSERT_NE(animation, nullptr);
  const std::vector<float> times = keyframe_times(model, *animation);
  ASSERT_EQ(times.size(), c.frame_globals.size());
  for (size_t k = 0; k < times.size(); ++k) {
    const double expected_time = static_cast<double>(k) / c.frames_per_second;
    EXPECT_NEAR(times[k], expected_time, 1e-6 * std::max(1.0, expected_time)) << what << ": frame " << k;
    for (const Rotations rotations : {Rotations::kSpecSlerp, Rotations::kNaiveNlerp}) {
      const Eigen::MatrixX3d posed = skin_from_file(model, node_globals(model, animation, times[k], rotations));
      const Eigen::MatrixX3d expected = skin_directly(c, c.frame_globals[k]);
      EXPECT_LE(max_distance(posed, expected), tolerance) << what << ": frame " << k;
    }
  }
}

// --- Tests --------------------------------------------------------------------------------------

TEST(GltfSkinWriterTest, GlbPosesEveryFrameAsTheCharacterAtEveryScale) {
  for (const double scale : {1.0, 1e-4, 1e4}) {
    const SkinnedCharacter c = make_character(scale);
    const auto bytes = serialize_skinned_glb(c);
    ASSERT_TRUE(bytes.ok()) << bytes.error().message;
    ASSERT_GE(bytes->size(), 12u);
    EXPECT_EQ(bytes->substr(0, 4), "glTF");
    const LoadedGltf loaded = load_gltf(*bytes, /*binary=*/true);
    ASSERT_TRUE(loaded.ok) << loaded.error;
    expect_poses_every_frame(loaded.model, c, "scale " + std::to_string(scale));
  }
}

TEST(GltfSkinWriterTest, GltfEmbedsItsBufferAndPosesTheSame) {
  const SkinnedCharacter c = make_character(1);
  const auto text = serialize_skinned_gltf(c);
  ASSERT_TRUE(text.ok()) << text.error().message;
  EXPECT_NE(text->find("data:application/octet-stream;base64,"), std::string::npos);
  const LoadedGltf loaded = load_gltf(*text, /*binary=*/false);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  expect_poses_every_frame(loaded.model, c, "gltf");
}

// Between keyframes the motion is the continuous one the frames sample (each local rotation turns
// steadily by less than 180° a frame), so half-way times must give frame k + ½ — also for a
// client that lerps quaternion components without looking at their signs, which spins the long
// way round wherever consecutive stored quaternions have a negative dot product.
TEST(GltfSkinWriterTest, HalfWayBetweenFramesFollowsTheShortArc) {
  const SkinnedCharacter c = make_character(1);
  const auto bytes = serialize_skinned_glb(c);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  const LoadedGltf loaded = load_gltf(*bytes, /*binary=*/true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Animation* animation = only_animation(loaded.model);
  ASSERT_NE(animation, nullptr);

  for (const tinygltf::AnimationChannel& channel : animation->channels) {
    if (channel.target_path != "rotation") continue;
    const std::vector<float> q =
        accessor_values<float>(loaded.model, animation->samplers.at(static_cast<size_t>(channel.sampler)).output,
                               TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC4);
    for (size_t k = 1; k < kFrames; ++k) {
      double dot = 0;
      for (size_t e = 0; e < 4; ++e) dot += static_cast<double>(q[4 * (k - 1) + e]) * q[4 * k + e];
      EXPECT_GE(dot, 0) << "node " << channel.target_node << " frames " << k - 1 << ", " << k;
    }
  }

  const std::vector<JointSpec> specs = joint_specs();
  const double tolerance = 1e-5 * size_of(c);
  for (int k = 0; k + 1 < kFrames; ++k) {
    const double frame = k + 0.5;
    const Eigen::MatrixX3d expected = skin_directly(c, globals_at(specs, frame, 1, /*animated=*/true));
    for (const Rotations rotations : {Rotations::kSpecSlerp, Rotations::kNaiveNlerp}) {
      const Eigen::MatrixX3d posed =
          skin_from_file(loaded.model, node_globals(loaded.model, animation, frame / kFps, rotations));
      EXPECT_LE(max_distance(posed, expected), tolerance)
          << "frame " << frame << (rotations == Rotations::kNaiveNlerp ? " (naive nlerp)" : " (slerp)");
    }
  }
}

TEST(GltfSkinWriterTest, DocumentLayout) {
  const SkinnedCharacter c = make_character(1);
  const auto bytes = serialize_skinned_glb(c);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  const LoadedGltf loaded = load_gltf(*bytes, /*binary=*/true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Model& model = loaded.model;
  const size_t joint_count = c.joint_parents.size();
  EXPECT_EQ(model.asset.version, "2.0");
  ASSERT_EQ(model.buffers.size(), 1u);

  // Joints are nodes 0 … J−1 with their names, children by parent; the mesh node J; two root
  // joints share the untransformed common root J + 1 (§3.7.3.2).
  ASSERT_EQ(model.nodes.size(), joint_count + 2);
  for (size_t j = 0; j < joint_count; ++j) {
    EXPECT_EQ(model.nodes[j].name, c.joint_names[j]);
    EXPECT_TRUE(model.nodes[j].scale.empty());
    for (const int child : model.nodes[j].children)
      EXPECT_EQ(c.joint_parents.at(static_cast<size_t>(child)), static_cast<int32_t>(j));
  }
  const tinygltf::Node& mesh_node = model.nodes[joint_count];
  EXPECT_EQ(mesh_node.mesh, 0);
  EXPECT_EQ(mesh_node.skin, 0);
  EXPECT_TRUE(mesh_node.translation.empty() && mesh_node.rotation.empty() && mesh_node.matrix.empty());
  const tinygltf::Node& common_root = model.nodes[joint_count + 1];
  EXPECT_EQ(common_root.children, (std::vector<int>{0, 6}));
  // Named after the character: importers name their objects after these (issue #55 item 13).
  EXPECT_EQ(mesh_node.name, c.name);
  EXPECT_EQ(model.meshes.at(0).name, c.name);
  EXPECT_EQ(model.skins.at(0).name, c.name + " rig");
  EXPECT_EQ(common_root.name, c.name + " rig");
  EXPECT_TRUE(common_root.translation.empty() && common_root.rotation.empty() && common_root.matrix.empty());
  ASSERT_EQ(model.scenes.size(), 1u);
  EXPECT_EQ(model.scenes[0].nodes,
            (std::vector<int>{static_cast<int>(joint_count), static_cast<int>(joint_count) + 1}));
  ASSERT_EQ(model.skins.size(), 1u);
  EXPECT_EQ(model.skins[0].skeleton, static_cast<int>(joint_count) + 1);
  EXPECT_EQ(model.skins[0].joints, (std::vector<int>{0, 1, 2, 3, 4, 5, 6}));

  // Six influences at most: two JOINTS/WEIGHTS sets; POSITION with its bounds; outward unit
  // normals (the tube's faces are wound outwards); uint32 indices.
  const tinygltf::Primitive& primitive = model.meshes.at(0).primitives.at(0);
  EXPECT_EQ(primitive.attributes.count("JOINTS_1"), 1u);
  EXPECT_EQ(primitive.attributes.count("WEIGHTS_1"), 1u);
  EXPECT_EQ(primitive.attributes.count("JOINTS_2"), 0u);
  const tinygltf::Accessor& positions = model.accessors.at(static_cast<size_t>(primitive.attributes.at("POSITION")));
  ASSERT_EQ(positions.minValues.size(), 3u);
  ASSERT_EQ(positions.maxValues.size(), 3u);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_EQ(positions.minValues[static_cast<size_t>(axis)], static_cast<float>(c.bind_points.col(axis).minCoeff()));
    EXPECT_EQ(positions.maxValues[static_cast<size_t>(axis)], static_cast<float>(c.bind_points.col(axis).maxCoeff()));
  }
  const std::vector<float> normals = accessor_values<float>(model, primitive.attributes.at("NORMAL"),
                                                            TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3);
  ASSERT_EQ(normals.size(), 3 * static_cast<size_t>(c.bind_points.rows()));
  for (Eigen::Index v = 0; v < c.bind_points.rows(); ++v) {
    const Eigen::Vector3d n(normals[3 * static_cast<size_t>(v)], normals[3 * static_cast<size_t>(v) + 1],
                            normals[3 * static_cast<size_t>(v) + 2]);
    EXPECT_NEAR(n.norm(), 1, 1e-6) << "vertex " << v;
    const double x = c.bind_points(v, 0);
    const Eigen::Vector3d radial = c.bind_points.row(v).transpose() - Eigen::Vector3d(x, 0.2 * x * x, 0);
    EXPECT_GT(n.dot(radial.normalized()), 0.5) << "vertex " << v;
  }
  const std::vector<uint32_t> indices =
      accessor_values<uint32_t>(model, primitive.indices, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR);
  ASSERT_EQ(indices.size(), static_cast<size_t>(c.faces.size()));
  for (size_t i = 0; i < indices.size(); ++i) EXPECT_EQ(indices[i], static_cast<uint32_t>(c.faces.data()[i]));

  // One animation: a translation and a rotation channel per joint, LINEAR, on one time accessor
  // whose min/max §3.11 requires.
  const tinygltf::Animation* animation = only_animation(model);
  ASSERT_NE(animation, nullptr);
  EXPECT_EQ(animation->name, "wave");
  ASSERT_EQ(animation->channels.size(), 2 * joint_count);
  for (size_t j = 0; j < joint_count; ++j) {
    int paths = 0;
    for (const tinygltf::AnimationChannel& channel : animation->channels) {
      if (channel.target_node != static_cast<int>(j)) continue;
      paths += channel.target_path == "translation" ? 1 : channel.target_path == "rotation" ? 2 : 100;
      const tinygltf::AnimationSampler& sampler = animation->samplers.at(static_cast<size_t>(channel.sampler));
      EXPECT_EQ(sampler.interpolation, "LINEAR");
      EXPECT_EQ(sampler.input, animation->samplers[0].input);
    }
    EXPECT_EQ(paths, 3) << "joint " << j;
  }
  const tinygltf::Accessor& input = model.accessors.at(static_cast<size_t>(animation->samplers[0].input));
  EXPECT_EQ(input.minValues, (std::vector<double>{0.0}));
  EXPECT_EQ(input.maxValues, (std::vector<double>{static_cast<float>((kFrames - 1) / kFps)}));
}

// The library's own reader sees the skin the character describes: joints, names, parents,
// inverse binds, the bind pose of the joint nodes, the mesh and every influence slot.
TEST(GltfSkinWriterTest, ReadGltfSkinAgreesWithTheCharacter) {
  const double scale = 3;
  const SkinnedCharacter c = make_character(scale);
  TempDir dir;
  const Status written = write_skinned_character(dir / "character.glb", c);
  ASSERT_TRUE(written.ok()) << written.error().message;
  const auto skin = read_gltf_skin(dir / "character.glb");
  ASSERT_TRUE(skin.ok()) << skin.error().message;
  const size_t joint_count = c.joint_parents.size();
  EXPECT_EQ(skin->joint_parents, c.joint_parents);
  EXPECT_EQ(skin->joint_names, c.joint_names);
  ASSERT_EQ(skin->inverse_bind_matrices.size(), joint_count);
  ASSERT_EQ(skin->joint_node_transforms.size(), joint_count);
  for (size_t j = 0; j < joint_count; ++j) {
    const Eigen::Matrix4d inverse = c.bind_globals[j].inverse();
    EXPECT_LE((skin->inverse_bind_matrices[j] - inverse).cwiseAbs().maxCoeff(), 1e-6 * scale) << "joint " << j;
    EXPECT_LE((skin->joint_node_transforms[j] - c.bind_globals[j]).cwiseAbs().maxCoeff(), 1e-9 * scale)
        << "joint " << j;
  }
  ASSERT_EQ(skin->points.rows(), c.bind_points.rows());
  EXPECT_LE((skin->points - c.bind_points).cwiseAbs().maxCoeff(), 1e-6 * scale);
  EXPECT_TRUE(skin->faces == c.faces);

  // Two sets of four slots each: the influences in order (a zero weight's joint written as 0),
  // then joint 0 with weight 0.
  const size_t vertex_count = static_cast<size_t>(c.bind_points.rows());
  ASSERT_EQ(skin->slot_offsets.size(), vertex_count + 1);
  for (size_t v = 0; v < vertex_count; ++v) {
    ASSERT_EQ(skin->slot_offsets[v + 1] - skin->slot_offsets[v], 8) << "vertex " << v;
    const size_t first = static_cast<size_t>(c.offsets[v]), count = static_cast<size_t>(c.offsets[v + 1]) - first;
    for (size_t slot = 0; slot < 8; ++slot) {
      const size_t at = static_cast<size_t>(skin->slot_offsets[v]) + slot;
      const double weight = slot < count ? c.weights[first + slot] : 0;
      const int32_t joint = weight == 0 ? 0 : c.joints[first + slot];
      EXPECT_EQ(skin->slot_joints[at], joint) << "vertex " << v << " slot " << slot;
      EXPECT_EQ(skin->slot_weights[at], static_cast<float>(weight)) << "vertex " << v << " slot " << slot;
    }
  }
}

TEST(GltfSkinWriterTest, WritesByExtensionAndRefusesOthers) {
  const SkinnedCharacter c = make_character(1);
  TempDir dir;
  ASSERT_TRUE(write_skinned_character(dir / "a.glb", c).ok());
  ASSERT_TRUE(write_skinned_character(dir / "a.GLTF", c).ok());
  const auto glb = read_whole_file(dir / "a.glb");
  ASSERT_TRUE(glb.ok());
  EXPECT_EQ(*glb, *serialize_skinned_glb(c));
  const auto gltf = read_whole_file(dir / "a.GLTF");
  ASSERT_TRUE(gltf.ok());
  EXPECT_EQ(*gltf, *serialize_skinned_gltf(c));
  const auto read_back = read_gltf_skin(dir / "a.GLTF");
  ASSERT_TRUE(read_back.ok()) << read_back.error().message;
  EXPECT_EQ(read_back->joint_names, c.joint_names);

  for (const std::string name : {"a.fbx", "a", "a.obj", "a.glb.tmp"}) {
    const Status status = write_skinned_character(dir / name, c);
    ASSERT_FALSE(status.ok()) << name;
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument) << name;
    EXPECT_NE(status.error().message.find(name), std::string::npos) << status.error().message;
    EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  }
  const Status missing_dir = write_skinned_character(dir / "no" / "such" / "a.glb", c);
  ASSERT_FALSE(missing_dir.ok());
  EXPECT_EQ(missing_dir.error().code, ErrorCode::kIo);
}

TEST(GltfSkinWriterTest, WithoutAnimationOneRootAndGivenNormals) {
  // A three-joint chain, no frames, normals given (then written as given, not recomputed).
  SkinnedCharacter c = make_character(1);
  c.joint_parents = {-1, 0, 1};
  c.joint_names.clear();
  c.bind_globals.resize(3);
  c.frame_globals.clear();
  c.normals = Eigen::MatrixX3d::Zero(c.bind_points.rows(), 3);
  c.normals.col(1).setOnes();
  c.offsets = {0};
  c.joints.clear();
  c.weights.clear();
  for (Eigen::Index v = 0; v < c.bind_points.rows(); ++v) {
    c.joints.insert(c.joints.end(), {0, 1, 2});
    c.weights.insert(c.weights.end(), {0.5, 0.25, 0.25});
    c.offsets.push_back(static_cast<int32_t>(c.joints.size()));
  }
  const auto bytes = serialize_skinned_glb(c);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  const LoadedGltf loaded = load_gltf(*bytes, /*binary=*/true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Model& model = loaded.model;
  EXPECT_TRUE(model.animations.empty());
  ASSERT_EQ(model.nodes.size(), 4u);  // three joints and the mesh: the root joint is the common root
  EXPECT_EQ(model.nodes[0].name, "joint_0");
  EXPECT_EQ(model.nodes[2].name, "joint_2");
  EXPECT_EQ(model.skins.at(0).skeleton, 0);
  EXPECT_EQ(model.scenes.at(0).nodes, (std::vector<int>{3, 0}));
  const tinygltf::Primitive& primitive = model.meshes.at(0).primitives.at(0);
  EXPECT_EQ(primitive.attributes.count("JOINTS_1"), 0u);
  const std::vector<float> normals = accessor_values<float>(model, primitive.attributes.at("NORMAL"),
                                                            TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3);
  for (size_t v = 0; v < normals.size() / 3; ++v) {
    EXPECT_EQ(normals[3 * v], 0.0f);
    EXPECT_EQ(normals[3 * v + 1], 1.0f);
    EXPECT_EQ(normals[3 * v + 2], 0.0f);
  }
  const Eigen::MatrixX3d bind = skin_from_file(model, node_globals(model, nullptr, 0, Rotations::kSpecSlerp));
  EXPECT_LE(max_distance(bind, c.bind_points), 1e-5 * size_of(c));

  // Without normals and with a vertex in no face, NORMAL is left out rather than made up.
  SkinnedCharacter isolated = c;
  isolated.normals.resize(0, 3);
  isolated.bind_points.conservativeResize(c.bind_points.rows() + 1, 3);
  isolated.bind_points.row(c.bind_points.rows()) = Eigen::RowVector3d(9, 9, 9);
  isolated.joints.push_back(0);
  isolated.weights.push_back(1);
  isolated.offsets.push_back(static_cast<int32_t>(isolated.joints.size()));
  const auto without = serialize_skinned_glb(isolated);
  ASSERT_TRUE(without.ok()) << without.error().message;
  const LoadedGltf loaded_without = load_gltf(*without, /*binary=*/true);
  ASSERT_TRUE(loaded_without.ok) << loaded_without.error;
  EXPECT_EQ(loaded_without.model.meshes.at(0).primitives.at(0).attributes.count("NORMAL"), 0u);
}

// Issue #51: joints that shear, scale and reflect (an articulated model's bones), each written as
// a shape node (T, U, Σ) above its joint node (Vᵀ), and morph targets added before skinning,
// their weights animated: every keyframe posed from the file alone — TRS with scale, morph
// weights, §3.7.2.2 and §3.7.3.3 — against skinning computed here from the character.
TEST(GltfSkinWriterTest, AffineJointsAndMorphTargetsPoseEveryFrame) {
  SkinnedCharacter c = make_character(1);
  c.affine_joints = true;
  // Joint j's global gets a shear and an uneven scale that change with the frame; joint 4 is
  // mirrored (det < 0, a negative scale in the file); the bind pose is sheared too.
  const auto deform = [](size_t j, double k) {
    Eigen::Matrix4d d = Eigen::Matrix4d::Identity();
    d(0, 1) = 0.3 * std::sin(0.7 * k + static_cast<double>(j));
    d(2, 0) = -0.2 * std::cos(0.4 * k + static_cast<double>(j));
    d(1, 1) = 1.0 + 0.25 * std::sin(0.5 * k + 2.0 * static_cast<double>(j));
    if (j == 4) d(0, 0) = -1.2;
    return d;
  };
  for (size_t j = 0; j < c.bind_globals.size(); ++j) c.bind_globals[j] = c.bind_globals[j] * deform(j, -1);
  for (size_t k = 0; k < c.frame_globals.size(); ++k) {
    for (size_t j = 0; j < c.frame_globals[k].size(); ++j) {
      c.frame_globals[k][j] = c.frame_globals[k][j] * deform(j, static_cast<double>(k));
    }
  }
  std::mt19937 random(11);
  std::uniform_real_distribution<double> offset(-0.2, 0.2);
  for (int t = 0; t < 2; ++t) {
    Eigen::MatrixX3d target(c.bind_points.rows(), 3);
    for (Eigen::Index v = 0; v < target.rows(); ++v) target.row(v) << offset(random), offset(random), offset(random);
    c.morph_targets.push_back(target);
  }
  c.morph_target_names = {"bulge", ""};
  c.frame_morph_weights.resize(kFrames, 2);
  for (int k = 0; k < kFrames; ++k) c.frame_morph_weights.row(k) << std::sin(0.9 * k), 1.5 - 0.4 * k;

  const auto bytes = serialize_skinned_glb(c);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  const LoadedGltf loaded = load_gltf(*bytes, true);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  const tinygltf::Model& model = loaded.model;
  const size_t J = c.joint_parents.size();
  ASSERT_EQ(model.nodes.size(), 2 * J + 2) << "a joint node and a shape node per joint, the mesh, the common root";
  EXPECT_EQ(model.nodes[J + 2 + 4].scale.size(), 3u);
  const tinygltf::Mesh& mesh = model.meshes.at(0);
  ASSERT_EQ(mesh.primitives.at(0).targets.size(), 2u);
  EXPECT_EQ(mesh.weights, std::vector<double>({0.0, 0.0}));
  const tinygltf::Value& names = mesh.extras.Get("targetNames");
  ASSERT_TRUE(names.IsArray());
  EXPECT_EQ(names.Get(0).Get<std::string>(), "bulge");
  EXPECT_EQ(names.Get(1).Get<std::string>(), "target_1");

  const double tolerance = 1e-5 * size_of(c);
  const Eigen::MatrixX3d bind =
      skin_from_file(model, node_globals(model, nullptr, 0, Rotations::kSpecSlerp), morph_weights_at(model, nullptr, 0));
  EXPECT_LE(max_distance(bind, c.bind_points), tolerance) << "bind pose";
  const tinygltf::Animation* animation = only_animation(model);
  ASSERT_NE(animation, nullptr);
  const std::vector<float> times = keyframe_times(model, *animation);
  ASSERT_EQ(times.size(), static_cast<size_t>(kFrames));
  for (size_t k = 0; k < times.size(); ++k) {
    SkinnedCharacter morphed = c;
    for (size_t t = 0; t < 2; ++t) {
      morphed.bind_points += c.frame_morph_weights(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(t)) *
                             c.morph_targets[t];
    }
    const Eigen::MatrixX3d expected = skin_directly(morphed, c.frame_globals[k]);
    for (const Rotations rotations : {Rotations::kSpecSlerp, Rotations::kNaiveNlerp}) {
      const Eigen::MatrixX3d posed = skin_from_file(model, node_globals(model, animation, times[k], rotations),
                                                    morph_weights_at(model, animation, times[k]));
      EXPECT_LE(max_distance(posed, expected), tolerance) << "frame " << k;
    }
  }
}

TEST(GltfSkinWriterTest, RefusesBadCharactersNamingTheField) {
  const SkinnedCharacter good = make_character(1);
  struct Case {
    const char* what;
    std::function<void(SkinnedCharacter&)> spoil;
    const char* expected;  // a part of the message
  };
  const std::vector<Case> cases = {
      {"no vertices", [](SkinnedCharacter& c) { c.bind_points.resize(0, 3); }, "bind_points"},
      {"NaN point", [](SkinnedCharacter& c) { c.bind_points(3, 1) = kNaN; }, "bind_points row 3"},
      {"no faces", [](SkinnedCharacter& c) { c.faces.resize(0, 3); }, "faces has no rows"},
      {"face index", [](SkinnedCharacter& c) { c.faces(4, 2) = 48; }, "faces(4, 2) = 48"},
      {"negative face index", [](SkinnedCharacter& c) { c.faces(0, 0) = -1; }, "faces(0, 0) = -1"},
      {"normal rows", [](SkinnedCharacter& c) { c.normals = Eigen::MatrixX3d::Ones(3, 3); }, "normals has 3 rows"},
      {"normal length",
       [](SkinnedCharacter& c) {
         c.normals = Eigen::MatrixX3d::Zero(c.bind_points.rows(), 3);
         c.normals.col(0).setOnes();
         c.normals(5, 0) = 2;
       },
       "normals row 5"},
      {"no joints", [](SkinnedCharacter& c) { c.joint_parents.clear(); }, "joint_parents is empty"},
      {"child before parent", [](SkinnedCharacter& c) { c.joint_parents[2] = 5; }, "joint_parents[2] = 5"},
      {"own parent", [](SkinnedCharacter& c) { c.joint_parents[3] = 3; }, "joint_parents[3] = 3"},
      {"parent below -1", [](SkinnedCharacter& c) { c.joint_parents[1] = -2; }, "joint_parents[1] = -2"},
      {"name count", [](SkinnedCharacter& c) { c.joint_names.pop_back(); }, "joint_names has 6 names"},
      {"bind count", [](SkinnedCharacter& c) { c.bind_globals.pop_back(); }, "bind_globals has 6"},
      {"bind NaN", [](SkinnedCharacter& c) { c.bind_globals[1](0, 3) = kNaN; }, "bind_globals[1] has a non-finite"},
      {"bind scaled", [](SkinnedCharacter& c) { c.bind_globals[2].topLeftCorner<3, 3>() *= 1.01; },
       "bind_globals[2] is not rigid"},
      {"bind reflected", [](SkinnedCharacter& c) { c.bind_globals[4].col(0) *= -1; },
       "bind_globals[4] is not a rotation"},
      {"bind last row", [](SkinnedCharacter& c) { c.bind_globals[0](3, 0) = 0.5; }, "bind_globals[0] has last row"},
      {"offsets size", [](SkinnedCharacter& c) { c.offsets.pop_back(); }, "offsets has 48 entries"},
      {"offsets start", [](SkinnedCharacter& c) { c.offsets[0] = 1; }, "offsets[0] = 1"},
      {"offsets decrease", [](SkinnedCharacter& c) { std::swap(c.offsets[10], c.offsets[11]); }, "offsets[11]"},
      {"offsets end", [](SkinnedCharacter& c) { c.offsets.back() -= 1; }, "offsets[48]"},
      {"offsets huge", [](SkinnedCharacter& c) { c.offsets[20] = std::numeric_limits<int32_t>::max(); },
       "past the end of joints"},
      {"weights size", [](SkinnedCharacter& c) { c.weights.pop_back(); }, "weights has"},
      {"joint index", [](SkinnedCharacter& c) { c.joints[7] = 7; }, "joints[7]"},
      {"negative joint", [](SkinnedCharacter& c) { c.joints[8] = -1; }, "joints[8]"},
      {"negative weight",  // vertex 0 (two influences) still sums to 1: only the sign is wrong
       [](SkinnedCharacter& c) {
         c.weights[0] = 1.25;
         c.weights[1] = -0.25;
       },
       "weights[1] (vertex 0) = -0.25"},
      {"NaN weight", [](SkinnedCharacter& c) { c.weights[3] = kNaN; }, "weights[3]"},
      {"sum", [](SkinnedCharacter& c) { c.weights[2] *= 0.9; }, "weights of vertex 1 (entries [2, 5)) sum to"},
      {"repeated joint",
       [](SkinnedCharacter& c) {
         c.joints[1] = c.joints[0];  // vertex 0: two influences on the same joint
       },
       "appears twice"},
      {"frame joint count", [](SkinnedCharacter& c) { c.frame_globals[2].pop_back(); }, "frame_globals[2] has 6"},
      {"frame not rigid", [](SkinnedCharacter& c) { c.frame_globals[1][3](1, 2) += 0.01; }, "frame_globals[1][3]"},
      {"frame infinite",
       [](SkinnedCharacter& c) { c.frame_globals[6][6](2, 3) = std::numeric_limits<double>::infinity(); },
       "frame_globals[6][6] has a non-finite"},
      {"fps zero", [](SkinnedCharacter& c) { c.frames_per_second = 0; }, "frames_per_second = 0"},
      {"fps negative", [](SkinnedCharacter& c) { c.frames_per_second = -24; }, "frames_per_second = -24"},
      {"fps NaN", [](SkinnedCharacter& c) { c.frames_per_second = kNaN; }, "frames_per_second"},
      {"fps too high", [](SkinnedCharacter& c) { c.frames_per_second = 1e50; }, "same float32 time"},
      {"affine singular",
       [](SkinnedCharacter& c) {
         c.affine_joints = true;
         c.frame_globals[3][2].row(1).head<3>().setZero();
       },
       "frame_globals[3][2] is singular"},
      {"morph target rows",
       [](SkinnedCharacter& c) {
         c.morph_targets = {Eigen::MatrixX3d::Zero(5, 3)};
         c.frame_morph_weights = Eigen::MatrixXd::Zero(kFrames, 1);
       },
       "morph_targets[0] has 5 rows"},
      {"morph weights shape",
       [](SkinnedCharacter& c) {
         c.morph_targets = {Eigen::MatrixX3d::Zero(c.bind_points.rows(), 3)};
         c.frame_morph_weights = Eigen::MatrixXd::Zero(kFrames - 1, 1);
       },
       "frame_morph_weights is 6×1, expected 7×1"},
      {"morph NaN",
       [](SkinnedCharacter& c) {
         c.morph_targets = {Eigen::MatrixX3d::Zero(c.bind_points.rows(), 3)};
         c.morph_targets[0](2, 2) = kNaN;
         c.frame_morph_weights = Eigen::MatrixXd::Zero(kFrames, 1);
       },
       "morph_targets[0] has a non-finite"},
  };
  for (const Case& test : cases) {
    SkinnedCharacter c = good;
    test.spoil(c);
    for (const bool binary : {true, false}) {
      const auto bytes = binary ? serialize_skinned_glb(c) : serialize_skinned_gltf(c);
      ASSERT_FALSE(bytes.ok()) << test.what;
      EXPECT_EQ(bytes.error().code, ErrorCode::kInvalidArgument) << test.what;
      EXPECT_NE(bytes.error().message.find(test.expected), std::string::npos)
          << test.what << ": " << bytes.error().message;
    }
    TempDir dir;
    const Status status = write_skinned_character(dir / "bad.glb", c);
    ASSERT_FALSE(status.ok()) << test.what;
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument) << test.what;
    EXPECT_NE(status.error().message.find((dir / "bad.glb").string()), std::string::npos) << status.error().message;
    EXPECT_FALSE(std::filesystem::exists(dir / "bad.glb")) << test.what;
  }

  // Without frames the rate is not used, so any value passes.
  SkinnedCharacter still = good;
  still.frame_globals.clear();
  still.frames_per_second = 0;
  EXPECT_TRUE(serialize_skinned_glb(still).ok());
}

}  // namespace
}  // namespace animspace::mesh_io
