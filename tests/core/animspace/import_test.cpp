#include "core/animspace/import.h"
#include "core/mesh_io/gltf_skin.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/mesh_io/libigl_rig.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "tests/support/animspace_fixtures.h"
#include "harness/gltf_builder.h"
#include "tests/support/test_support.h"

namespace animspace::animation_space {
namespace {

using testing::random_pose;
using testing::random_skeleton;
using testing::TempDir;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// ---------------------------------------------------------------------------------------------
// from_linear_blend (Merry 2007 §3.1)

// A random SSD model: random rest points, 1–4 influences per vertex with positive weights
// summing to 1, plus an exact-zero weight on every third vertex (which must not become an
// influence).
LinearBlendModel random_linear_blend(const Skeleton& skeleton, int vertices, uint64_t seed, double extent = 1.0) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.1, 1.0);
  LinearBlendModel model;
  model.skeleton = skeleton;
  model.rest_points.resize(3, vertices);
  std::vector<double> weights;
  const int b = skeleton.bone_count();
  for (int i = 0; i < vertices; ++i) {
    model.rest_points.col(i) = extent * Eigen::Vector3d(normal(engine), normal(engine), normal(engine));
    std::vector<int32_t> bones;
    const int count = std::min(b, std::uniform_int_distribution<int>(1, 4)(engine));
    while (static_cast<int>(bones.size()) < count) {
      const int bone = std::uniform_int_distribution<int>(0, b - 1)(engine);
      if (std::find(bones.begin(), bones.end(), bone) == bones.end()) bones.push_back(bone);
    }
    std::sort(bones.begin(), bones.end());
    std::vector<double> w(bones.size());
    double sum = 0;
    for (double& x : w) sum += (x = uniform(engine));
    for (size_t k = 0; k < bones.size(); ++k) {
      // Vertices 0, 3, 6 … give their first bone weight 0 when they have more than one.
      const bool zero = i % 3 == 0 && k == 0 && bones.size() > 1;
      model.influences.bones.push_back(bones[k]);
      weights.push_back(zero ? 0.0 : w[k] / (sum - (i % 3 == 0 && bones.size() > 1 ? w[0] : 0.0)));
    }
    model.influences.offsets.push_back(static_cast<int32_t>(model.influences.bones.size()));
  }
  model.weights = Eigen::Map<Eigen::VectorXd>(weights.data(), static_cast<Eigen::Index>(weights.size()));
  return model;
}

// Eq. 2.2 written out, independently of model.cpp: v = Σ_j w_j G_j Ĝ_j⁻¹ v̂ with a general
// 4×4 inverse.
Eigen::Vector3d ssd_point(const LinearBlendModel& model, const TransformList& globals, int i) {
  Eigen::Vector4d v = Eigen::Vector4d::Zero();
  for (int k = model.influences.begin(i); k < model.influences.end(i); ++k) {
    const size_t j = static_cast<size_t>(model.influences.bones[static_cast<size_t>(k)]);
    v += model.weights(k) * globals[j] * model.skeleton.rest[j].inverse() * model.rest_points.col(i).homogeneous();
  }
  return v.head<3>();
}

TEST(ImportFromLinearBlendTest, PosesLikeSsdAndDropsOnlyZeroWeights) {
  const Skeleton skeleton = random_skeleton(6, 21);
  const LinearBlendModel ssd = random_linear_blend(skeleton, 300, 22);
  ASSERT_TRUE(validate(ssd).ok());
  const AnimationSpaceModel model = from_linear_blend(ssd);
  ASSERT_TRUE(validate(model, 1e-12).ok()) << validate(model).error().message;

  int zeros = 0;
  for (Eigen::Index k = 0; k < ssd.weights.size(); ++k) zeros += ssd.weights(k) == 0.0;
  ASSERT_GT(zeros, 0);
  EXPECT_EQ(model.influences.influence_count(), ssd.influences.influence_count() - zeros);
  EXPECT_EQ(model.vertex_count(), ssd.vertex_count());

  std::mt19937_64 engine(23);
  for (int pose = 0; pose < 5; ++pose) {
    // Pose 0 is the rest pose (G = Ĝ), which must give the rest mesh back.
    const TransformList globals = pose == 0 ? skeleton.rest : random_pose(skeleton, engine, 2.5);
    PointMatrix posed;
    evaluate(model, globals, posed);
    for (int i = 0; i < model.vertex_count(); ++i) {
      const Eigen::Vector3d expected = pose == 0 ? Eigen::Vector3d(ssd.rest_points.col(i)) : ssd_point(ssd, globals, i);
      EXPECT_LT((posed.row(i).cast<double>().transpose() - expected).norm(), 1e-5 * (1 + expected.norm()))
          << "pose " << pose << " vertex " << i;
    }
  }
}

// Scale robustness (STYLE §6): the conversion is exact at any scale of the rig.
TEST(ImportFromLinearBlendTest, ExactAtTinyAndHugeScales) {
  for (const double scale : {1e-4, 1e4}) {
    const Skeleton skeleton = random_skeleton(5, 31, scale);
    const LinearBlendModel ssd = random_linear_blend(skeleton, 100, 32, scale);
    const AnimationSpaceModel model = from_linear_blend(ssd);
    std::mt19937_64 engine(33);
    const TransformList globals = random_pose(skeleton, engine, 2.0);
    PointMatrix posed;
    evaluate(model, globals, posed);
    for (int i = 0; i < model.vertex_count(); ++i) {
      const Eigen::Vector3d expected = ssd_point(ssd, globals, i);
      EXPECT_LT((posed.row(i).cast<double>().transpose() - expected).norm(), 1e-5 * scale * (1 + expected.norm() / scale))
          << "scale " << scale << " vertex " << i;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// libigl rigs

// A small rig: joints 0 (hip) → 1 → 2 (a chain) and 0 → 3 (a branch); the TGF lists its bones
// children first, so the importer has to reorder them. Every vertex of a random point cloud gets
// random weights over all four bones, some exactly zero.
struct SmallLibiglRig {
  TriangleMesh rest;
  mesh_io::TgfSkeleton tgf;
  Eigen::MatrixXd weights;
};

SmallLibiglRig small_libigl_rig(uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  SmallLibiglRig rig;
  rig.tgf.joints.resize(4, 3);
  rig.tgf.joints << 0.1, 0.2, 0.3, 1.1, 0.2, 0.3, 2.0, 0.9, 0.3, 0.1, -0.8, 0.5;
  rig.tgf.bones.resize(3, 2);
  rig.tgf.bones << 1, 2,  // bone 0: its parent is bone 1, listed after it
      0, 1,               // bone 1: from the root joint
      0, 3;               // bone 2: a branch from the root joint
  const int vertices = 40;
  rig.rest.V.resize(vertices, 3);
  rig.weights.resize(vertices, 3);
  for (int i = 0; i < vertices; ++i) {
    rig.rest.V.row(i) = Eigen::RowVector3f(static_cast<float>(2 * uniform(engine)), static_cast<float>(normal(engine)),
                                           static_cast<float>(normal(engine)));
    double sum = 0;
    for (int b = 0; b < 3; ++b) sum += (rig.weights(i, b) = (i + b) % 4 == 0 ? 0.0 : uniform(engine));
    rig.weights.row(i) /= sum;
  }
  rig.rest.F.resize(vertices - 2, 3);
  for (int f = 0; f < vertices - 2; ++f) rig.rest.F.row(f) << f, f + 1, f + 2;
  return rig;
}

std::vector<Eigen::Matrix<double, 4, 3>> random_tmat(int bones, uint64_t seed) {
  std::mt19937_64 engine(seed);
  std::normal_distribution<double> normal;
  std::vector<Eigen::Matrix<double, 4, 3>> transforms;
  for (int b = 0; b < bones; ++b) {
    Eigen::Matrix<double, 4, 3> T;
    T.topRows<3>() = testing::random_rotation(engine).transpose();  // row-vector form of a rotation
    T.row(3) = Eigen::RowVector3d(normal(engine), normal(engine), normal(engine));
    transforms.push_back(T);
  }
  return transforms;
}

TEST(ImportLibiglTest, HierarchyRestFramesAndTmatPoseMatchRowVectorSkinning) {
  const SmallLibiglRig files = small_libigl_rig(41);
  auto rig = rig_from_libigl(files.rest, files.tgf, files.weights);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const Skeleton& skeleton = rig->model.skeleton;
  ASSERT_EQ(skeleton.bone_count(), 4);
  ASSERT_TRUE(validate(skeleton).ok());
  const std::vector<int32_t>& ours = rig->bone_of_source;
  // Bone 0 ends at joint 2 and starts at joint 1, where bone 1 ends: bone 1 is its parent.
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(ours[0])], ours[1]);
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(ours[1])], 0);
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(ours[2])], 0);
  for (int b = 0; b < 3; ++b) {
    const Transform& rest = skeleton.rest[static_cast<size_t>(ours[static_cast<size_t>(b)])];
    const Eigen::Matrix3d linear = rest.topLeftCorner<3, 3>();
    const Eigen::Vector3d translation = rest.topRightCorner<3, 1>();
    EXPECT_TRUE(linear.isIdentity(0));
    EXPECT_EQ(translation, files.tgf.joints.row(files.tgf.bones(b, 0)).transpose()) << "bone " << b;
  }

  // posed_v = Σ_b W(v, b) [v 1] T_b, straight from the files' conventions.
  const auto tmat = random_tmat(3, 42);
  auto pose = pose_from_tmat(*rig, tmat, "test.Tmat");
  ASSERT_TRUE(pose.ok()) << pose.error().message;
  ASSERT_TRUE(validate_pose(skeleton, *pose, "pose").ok());
  EXPECT_TRUE((*pose)[0].isIdentity(0));
  const AnimationSpaceModel model = from_linear_blend(rig->model);
  PointMatrix posed;
  evaluate(model, *pose, posed);
  for (int v = 0; v < files.rest.V.rows(); ++v) {
    Eigen::RowVector3d expected = Eigen::RowVector3d::Zero();
    const Eigen::RowVector4d row(files.rest.V(v, 0), files.rest.V(v, 1), files.rest.V(v, 2), 1.0);
    for (int b = 0; b < 3; ++b) expected += files.weights(v, b) * (row * tmat[static_cast<size_t>(b)]);
    EXPECT_LT((posed.row(v).cast<double>() - expected).norm(), 1e-5) << "vertex " << v;
  }
  // Exact zeros are not influences.
  int nonzero = 0;
  for (Eigen::Index i = 0; i < files.weights.size(); ++i) nonzero += files.weights.data()[i] != 0.0;
  EXPECT_EQ(rig->model.influences.influence_count(), nonzero);
  EXPECT_EQ(rig->dropped_weights, 0);
}

TEST(ImportLibiglTest, ReadsFilesAndNamesThemInErrors) {
  TempDir dir;
  SmallLibiglRig files = small_libigl_rig(51);
  ASSERT_TRUE(mesh_io::write_triangle_mesh(dir / "rest.obj", files.rest).ok());
  ASSERT_TRUE(mesh_io::write_tgf(dir / "rig.tgf", files.tgf).ok());
  ASSERT_TRUE(mesh_io::write_dmat(dir / "rig.dmat", files.weights).ok());
  const auto tmat = random_tmat(3, 52);
  ASSERT_TRUE(mesh_io::write_tmat(dir / "pose.Tmat", tmat).ok());
  auto rig = read_libigl_rig(dir / "rest.obj", dir / "rig.tgf", dir / "rig.dmat");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  auto pose = read_tmat_pose(*rig, dir / "pose.Tmat");
  ASSERT_TRUE(pose.ok()) << pose.error().message;
  // The OBJ stores float32 coordinates, exactly what the in-memory rig holds.
  auto direct = rig_from_libigl(files.rest, files.tgf, files.weights);
  ASSERT_TRUE(direct.ok());
  EXPECT_EQ(rig->model.rest_points, direct->model.rest_points);
  EXPECT_EQ(rig->model.weights, direct->model.weights);

  // A DMAT row that does not sum to 1: the error names the file and the row.
  files.weights(7, 1) += 0.01;
  ASSERT_TRUE(mesh_io::write_dmat(dir / "bad.dmat", files.weights).ok());
  auto bad = read_libigl_rig(dir / "rest.obj", dir / "rig.tgf", dir / "bad.dmat");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(bad.error().message, "bad.dmat: row 7 (vertex 7): weights sum to 1.01, expected 1 (±1e-06)"))
      << bad.error().message;

  // A pose with the wrong number of bones.
  ASSERT_TRUE(mesh_io::write_tmat(dir / "short.Tmat", random_tmat(2, 53)).ok());
  auto short_pose = read_tmat_pose(*rig, dir / "short.Tmat");
  ASSERT_FALSE(short_pose.ok());
  EXPECT_TRUE(contains(short_pose.error().message, "short.Tmat: expected 3 transforms")) << short_pose.error().message;
}

TEST(ImportLibiglTest, RejectsShapeMismatchesAndNonTrees) {
  const SmallLibiglRig files = small_libigl_rig(61);
  const LibiglSources names{"m.obj", "s.tgf", "w.dmat"};
  {
    auto rig = rig_from_libigl(files.rest, files.tgf, files.weights.leftCols(2), names);
    ASSERT_FALSE(rig.ok());
    EXPECT_TRUE(contains(rig.error().message, "w.dmat: expected 40 rows")) << rig.error().message;
  }
  {
    mesh_io::TgfSkeleton two_parents = files.tgf;
    two_parents.bones(2, 1) = 2;  // bones 0 and 2 both end at joint 2
    auto rig = rig_from_libigl(files.rest, two_parents, files.weights, names);
    ASSERT_FALSE(rig.ok());
    EXPECT_TRUE(contains(rig.error().message, "s.tgf: bones 0 and 2 both end at joint 3")) << rig.error().message;
  }
  {
    mesh_io::TgfSkeleton cycle = files.tgf;
    cycle.bones(1, 0) = 2;  // bone 1 now runs 2 → 1 and bone 0 runs 1 → 2
    auto rig = rig_from_libigl(files.rest, cycle, files.weights, names);
    ASSERT_FALSE(rig.ok());
    EXPECT_TRUE(contains(rig.error().message, "s.tgf: the bones form a cycle")) << rig.error().message;
  }
  {
    Eigen::MatrixXd nan = files.weights;
    nan(3, 0) = std::nan("");
    auto rig = rig_from_libigl(files.rest, files.tgf, nan, names);
    ASSERT_FALSE(rig.ok());
    EXPECT_TRUE(contains(rig.error().message, "w.dmat: row 3 (vertex 3)")) << rig.error().message;
  }
}

// drop_below: tiny weights go, the rest are rescaled to sum to 1, and the report counts them.
TEST(ImportLibiglTest, DropBelowCountsAndRenormalises) {
  SmallLibiglRig files = small_libigl_rig(71);
  files.weights.row(5) << 1e-7, 0.5 - 1e-7, 0.5;
  files.weights.row(9) << 0.25, 2e-8, 0.75 - 2e-8;
  auto exact = rig_from_libigl(files.rest, files.tgf, files.weights);
  ASSERT_TRUE(exact.ok());
  EXPECT_EQ(exact->dropped_weights, 0);
  WeightOptions options;
  options.drop_below = 1e-6;
  auto rig = rig_from_libigl(files.rest, files.tgf, files.weights, {}, options);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_EQ(rig->dropped_weights, 2);
  EXPECT_DOUBLE_EQ(rig->max_dropped_weight_sum, 1e-7);
  EXPECT_EQ(rig->model.influences.end(5) - rig->model.influences.begin(5), 2);
  double sum = 0;
  for (int k = rig->model.influences.begin(5); k < rig->model.influences.end(5); ++k) sum += rig->model.weights(k);
  EXPECT_NEAR(sum, 1.0, 1e-15);
  options.drop_below = 2.0;  // drops everything
  auto none = rig_from_libigl(files.rest, files.tgf, files.weights, {}, options);
  ASSERT_FALSE(none.ok());
  EXPECT_TRUE(contains(none.error().message, "row 0 (vertex 0): no influence left")) << none.error().message;
}

// drop_budget (issue #55 item 11): a vertex's smallest weights go while their sum stays within the
// budget, the largest never; the rest are renormalised, and the vertex moves by exactly the dropped
// sum times the distance between where its dropped and its kept bones carry it.
TEST(ImportLibiglTest, DropBudgetDropsTheSmallestWeightsUpToTheirSum) {
  SmallLibiglRig files = small_libigl_rig(72);
  files.weights.row(4) << 4e-5, 5e-5, 1 - 9e-5;  // 9e-5 ≤ 1e-4: both small ones go
  files.weights.row(6) << 6e-5, 7e-5, 1 - 1.3e-4;  // 6e-5 goes; 6e-5 + 7e-5 > 1e-4: 7e-5 stays
  files.weights.row(8) << 0.5, 0.5, 0.0;           // nothing small: nothing goes
  WeightOptions options;
  options.drop_budget = 1e-4;
  auto rig = rig_from_libigl(files.rest, files.tgf, files.weights, {}, options);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const auto count = [&](int v) { return rig->model.influences.end(v) - rig->model.influences.begin(v); };
  EXPECT_EQ(count(4), 1);
  EXPECT_EQ(count(6), 2);
  EXPECT_EQ(count(8), 2);
  EXPECT_DOUBLE_EQ(rig->max_dropped_weight_sum, 9e-5);
  for (int v : {4, 6, 8}) {
    double sum = 0;
    for (int k = rig->model.influences.begin(v); k < rig->model.influences.end(v); ++k) sum += rig->model.weights(k);
    EXPECT_NEAR(sum, 1.0, 1e-15) << "vertex " << v;
  }
  // A budget as large as the whole weight still keeps the largest.
  options.drop_budget = 1.0;
  auto most = rig_from_libigl(files.rest, files.tgf, files.weights, {}, options);
  ASSERT_TRUE(most.ok()) << most.error().message;
  for (int v = 0; v < most->model.vertex_count(); ++v) {
    EXPECT_EQ(most->model.influences.end(v) - most->model.influences.begin(v), 1) << "vertex " << v;
  }
}

// ---------------------------------------------------------------------------------------------
// glTF 2.0 skins

using nlohmann::json;
using testing::GltfBuilder;

constexpr int kUnsignedByte = 5121, kUnsignedShort = 5123, kUnsignedInt = 5125, kFloat = 5126;

// glTF TRS of a node, as the spec composes it: T · R · S.
struct Trs {
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();

  Eigen::Matrix4d matrix() const {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = rotation.toRotationMatrix() * scale.asDiagonal();
    m.topRightCorner<3, 1>() = translation;
    return m;
  }
  json to_json() const {
    return {{"translation", {translation.x(), translation.y(), translation.z()}},
            {"rotation", {rotation.x(), rotation.y(), rotation.z(), rotation.w()}},
            {"scale", {scale.x(), scale.y(), scale.z()}}};
  }
};

// A bent box along x from 0 to 3 (rings of 4 vertices every 0.25), skinned to a chain of three
// joints at x = 0, 1, 2 under a non-joint "Armature" node; skin.joints lists them as
// (ankle, hip, knee) so that the importer must reorder them. The nodes carry a bent pose; the
// inverse bind matrices are those of the straight bind pose.
struct BentBox {
  std::vector<float> positions, normals;
  std::vector<uint32_t> indices;
  std::vector<std::array<int, 4>> joints;        // skin joint indices per slot
  std::vector<std::array<double, 4>> weights;    // per slot, summing to 1
  Trs armature, hip, knee, ankle;                // the file's (posed) node transforms
  Trs bind_armature, bind_hip, bind_knee, bind_ankle;
  int vertex_count() const { return static_cast<int>(positions.size() / 3); }

  // Skin joint j (file order: ankle, hip, knee) → global transforms, bind or posed.
  std::array<Eigen::Matrix4d, 3> globals(bool bind) const {
    const Eigen::Matrix4d a = (bind ? bind_armature : armature).matrix();
    const Eigen::Matrix4d h = a * (bind ? bind_hip : hip).matrix();
    const Eigen::Matrix4d k = h * (bind ? bind_knee : knee).matrix();
    const Eigen::Matrix4d n = k * (bind ? bind_ankle : ankle).matrix();
    return {n, h, k};
  }
};

BentBox bent_box() {
  BentBox box;
  const int rings = 13;
  for (int r = 0; r < rings; ++r) {
    const double x = 0.25 * r;
    for (int c = 0; c < 4; ++c) {
      const double y = (c == 0 || c == 3) ? -0.3 : 0.3, z = (c < 2) ? -0.3 : 0.3;
      box.positions.insert(box.positions.end(), {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)});
      const double length = std::sqrt(y * y + z * z);
      box.normals.insert(box.normals.end(), {0.0f, static_cast<float>(y / length), static_cast<float>(z / length)});
      // Hat functions centred on the joints' bones: hip bone 0..1, knee 1..2, ankle 2..3.
      std::array<double, 3> w{};  // hip, knee, ankle
      for (int b = 0; b < 3; ++b) w[static_cast<size_t>(b)] = std::max(0.0, 1.0 - std::abs(x - (b + 0.5)));
      const double sum = w[0] + w[1] + w[2];
      // Slots: skin joints are (ankle 0, hip 1, knee 2); one slot left unused (joint 0, weight 0).
      box.joints.push_back({1, 2, 0, 0});
      box.weights.push_back({w[0] / sum, w[1] / sum, w[2] / sum, 0.0});
    }
  }
  for (int r = 0; r + 1 < rings; ++r) {
    for (int c = 0; c < 4; ++c) {
      const uint32_t a = static_cast<uint32_t>(4 * r + c), b = static_cast<uint32_t>(4 * r + (c + 1) % 4);
      box.indices.insert(box.indices.end(), {a, b, b + 4, a, b + 4, a + 4});
    }
  }
  box.bind_armature.translation = Eigen::Vector3d(0.5, -0.25, 1.0);
  box.bind_armature.scale = Eigen::Vector3d(2.0, 2.0, 2.0);
  box.bind_knee.translation = box.bind_ankle.translation = Eigen::Vector3d(1, 0, 0);
  box.armature = box.bind_armature;
  box.hip = box.bind_hip;
  box.hip.rotation = Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitZ());
  box.knee = box.bind_knee;
  box.knee.rotation = Eigen::AngleAxisd(0.8, Eigen::Vector3d::UnitZ());
  box.ankle = box.bind_ankle;
  box.ankle.rotation = Eigen::AngleAxisd(-0.5, Eigen::Vector3d(0, 1, 1).normalized());
  return box;
}

struct BoxEncoding {
  int joint_type;   // kUnsignedByte or kUnsignedShort
  int weight_type;  // kFloat, kUnsignedByte or kUnsignedShort (normalised)
  GltfBuilder::Layout layout;
  const char* file;
};

// Weights as stored: float, or quantised with the rounding remainder on the largest slot so
// that the integers sum to the maximum exactly (as exporters do).
std::vector<double> stored_weights(const BentBox& box, int weight_type) {
  std::vector<double> out;
  const double max = weight_type == kUnsignedByte ? 255.0 : 65535.0;
  for (const auto& w : box.weights) {
    if (weight_type == kFloat) {
      for (double x : w) out.push_back(static_cast<float>(x));
      continue;
    }
    std::array<double, 4> q{};
    double total = 0;
    for (int s = 0; s < 4; ++s) total += (q[static_cast<size_t>(s)] = std::round(w[static_cast<size_t>(s)] * max));
    *std::max_element(q.begin(), q.end()) += max - total;
    for (double x : q) out.push_back(x);
  }
  return out;
}

GltfBuilder box_document(const BentBox& box, const BoxEncoding& encoding, bool with_normals = true) {
  GltfBuilder builder;
  const size_t n = static_cast<size_t>(box.vertex_count());
  const int position = builder.add(box.positions, kFloat, "VEC3", n);
  const int normal = builder.add(box.normals, kFloat, "VEC3", n);
  int joints;
  if (encoding.joint_type == kUnsignedByte) {
    std::vector<uint8_t> values;
    for (const auto& slot : box.joints) for (int j : slot) values.push_back(static_cast<uint8_t>(j));
    joints = builder.add(values, kUnsignedByte, "VEC4", n);
  } else {
    std::vector<uint16_t> values;
    for (const auto& slot : box.joints) for (int j : slot) values.push_back(static_cast<uint16_t>(j));
    joints = builder.add(values, kUnsignedShort, "VEC4", n);
  }
  const std::vector<double> stored = stored_weights(box, encoding.weight_type);
  int weights;
  if (encoding.weight_type == kFloat) {
    weights = builder.add(std::vector<float>(stored.begin(), stored.end()), kFloat, "VEC4", n);
  } else if (encoding.weight_type == kUnsignedByte) {
    weights = builder.add(std::vector<uint8_t>(stored.begin(), stored.end()), kUnsignedByte, "VEC4", n, true);
  } else {
    weights = builder.add(std::vector<uint16_t>(stored.begin(), stored.end()), kUnsignedShort, "VEC4", n, true);
  }
  const int indices = builder.add(box.indices, kUnsignedInt, "SCALAR", box.indices.size());
  std::vector<float> inverse_bind;
  for (const Eigen::Matrix4d& global : box.globals(true)) {
    const Eigen::Matrix4d inverse = global.inverse();
    for (int k = 0; k < 16; ++k) inverse_bind.push_back(static_cast<float>(inverse(k % 4, k / 4)));
  }
  const int ibm = builder.add(inverse_bind, kFloat, "MAT4", 3);
  json attributes = {{"POSITION", position}, {"JOINTS_0", joints}, {"WEIGHTS_0", weights}};
  if (with_normals) attributes["NORMAL"] = normal;
  builder.doc["meshes"] = {{{"primitives", {{{"attributes", attributes}, {"indices", indices}, {"mode", 4}}}}}};
  json armature = box.armature.to_json(), hip = box.hip.to_json(), knee = box.knee.to_json(),
       ankle = box.ankle.to_json();
  armature["name"] = "Armature";
  armature["children"] = {1};
  hip["name"] = "hip";
  hip["children"] = {2};
  knee["name"] = "knee";
  knee["children"] = {3};
  ankle["name"] = "ankle";
  // The mesh node's own transform must be ignored for a skinned mesh (glTF 2.0 §3.7.3.3).
  json mesh_node = {{"mesh", 0}, {"skin", 0}, {"translation", {5.0, 5.0, 5.0}}};
  builder.doc["nodes"] = {armature, hip, knee, ankle, mesh_node};
  builder.doc["skins"] = {{{"joints", {3, 1, 2}}, {"inverseBindMatrices", ibm}}};
  builder.doc["scenes"] = {{{"nodes", {0, 4}}}};
  builder.doc["scene"] = 0;
  return builder;
}

class ImportGltfTest : public ::testing::TestWithParam<BoxEncoding> {};

// Posing through animation space equals the glTF skinning equation computed here from the
// node TRS and the stored weights: v = Σ_slots w · (global(joint) · inverseBind(joint)) · v̂.
TEST_P(ImportGltfTest, PoseThroughAnimationSpaceEqualsGltfSkinning) {
  const BoxEncoding& encoding = GetParam();
  TempDir dir;
  const BentBox box = bent_box();
  box_document(box, encoding).write(dir / encoding.file, encoding.layout);
  auto gltf = read_gltf_rig(dir / encoding.file);
  ASSERT_TRUE(gltf.ok()) << gltf.error().message;
  const ImportedRig& rig = gltf->rig;
  ASSERT_EQ(rig.model.vertex_count(), box.vertex_count());
  ASSERT_EQ(rig.model.faces.rows(), static_cast<Eigen::Index>(box.indices.size() / 3));

  // Hierarchy: super-root → hip → knee → ankle, whatever the skin's order.
  const Skeleton& skeleton = rig.model.skeleton;
  ASSERT_EQ(skeleton.bone_count(), 4);
  const int ankle = rig.bone_of_source[0], hip = rig.bone_of_source[1], knee = rig.bone_of_source[2];
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(hip)], 0);
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(knee)], hip);
  EXPECT_EQ(skeleton.parents[static_cast<size_t>(ankle)], knee);
  EXPECT_EQ(skeleton.names[static_cast<size_t>(knee)], "knee");

  const auto bind = box.globals(true);
  const auto posed_globals = box.globals(false);
  for (int j = 0; j < 3; ++j) {
    const size_t bone = static_cast<size_t>(rig.bone_of_source[static_cast<size_t>(j)]);
    EXPECT_TRUE(skeleton.rest[bone].isApprox(bind[static_cast<size_t>(j)], 1e-6)) << "joint " << j;
    EXPECT_TRUE(gltf->pose[bone].isApprox(posed_globals[static_cast<size_t>(j)], 1e-12)) << "joint " << j;
  }

  const AnimationSpaceModel model = from_linear_blend(rig.model);
  PointMatrix posed;
  evaluate(model, gltf->pose, posed);
  const std::vector<double> stored = stored_weights(box, encoding.weight_type);
  const double max = encoding.weight_type == kFloat ? 1.0 : encoding.weight_type == kUnsignedByte ? 255.0 : 65535.0;
  double largest_error = 0;
  for (int v = 0; v < box.vertex_count(); ++v) {
    const Eigen::Vector4d rest(box.positions[3 * static_cast<size_t>(v)], box.positions[3 * static_cast<size_t>(v) + 1],
                               box.positions[3 * static_cast<size_t>(v) + 2], 1.0);
    Eigen::Vector4d expected = Eigen::Vector4d::Zero();
    for (int s = 0; s < 4; ++s) {
      const size_t joint = static_cast<size_t>(box.joints[static_cast<size_t>(v)][static_cast<size_t>(s)]);
      const Eigen::Matrix4d inverse_bind = bind[joint].inverse().cast<float>().cast<double>();
      expected += stored[4 * static_cast<size_t>(v) + static_cast<size_t>(s)] / max * posed_globals[joint] *
                  inverse_bind * rest;
    }
    largest_error = std::max(largest_error, (posed.row(v).cast<double>().transpose() - expected.head<3>()).norm());
  }
  // float32 inverse bind matrices and weights; a box about 6 units long after the armature's scale.
  EXPECT_LT(largest_error, 1e-5);

  // The NORMAL attribute comes back as stored.
  ASSERT_EQ(gltf->rest_normals.rows(), box.vertex_count());
  for (int v = 0; v < box.vertex_count(); ++v) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(gltf->rest_normals(v, c), box.normals[3 * static_cast<size_t>(v) + static_cast<size_t>(c)]);
  }
}

// mesh_io::read_gltf_skin gives the file as it stands: the skin's own joint order and hierarchy,
// and each vertex's four JOINTS_0 / WEIGHTS_0 slots as stored (normalised integers divided by
// their maximum), before any rig convention.
TEST_P(ImportGltfTest, SkinReaderGivesTheStoredSlotsInTheSkinsOrder) {
  const BoxEncoding& encoding = GetParam();
  TempDir dir;
  const BentBox box = bent_box();
  box_document(box, encoding).write(dir / encoding.file, encoding.layout);
  auto skin = mesh_io::read_gltf_skin(dir / encoding.file);
  ASSERT_TRUE(skin.ok()) << skin.error().message;
  // Skin order: ankle, hip, knee — ankle's parent is knee (2), knee's is hip (1), hip is a root.
  EXPECT_EQ(skin->joint_parents, (std::vector<int32_t>{2, -1, 1}));
  EXPECT_EQ(skin->joint_names[2], "knee");
  ASSERT_EQ(skin->points.rows(), box.vertex_count());
  ASSERT_EQ(skin->slot_offsets.size(), static_cast<size_t>(box.vertex_count()) + 1);
  const std::vector<double> stored = stored_weights(box, encoding.weight_type);
  const double max = encoding.weight_type == kFloat ? 1.0 : encoding.weight_type == kUnsignedByte ? 255.0 : 65535.0;
  for (int v = 0; v < box.vertex_count(); ++v) {
    const auto first = static_cast<size_t>(skin->slot_offsets[static_cast<size_t>(v)]);
    ASSERT_EQ(skin->slot_offsets[static_cast<size_t>(v) + 1] - skin->slot_offsets[static_cast<size_t>(v)], 4);
    for (size_t s = 0; s < 4; ++s) {
      EXPECT_EQ(skin->slot_joints[first + s], box.joints[static_cast<size_t>(v)][s]);
      EXPECT_NEAR(skin->slot_weights[first + s], stored[4 * static_cast<size_t>(v) + s] / max, 1e-7);  // float32 as stored
    }
  }
  const auto bind = box.globals(true);
  for (size_t j = 0; j < 3; ++j) {
    EXPECT_TRUE(skin->inverse_bind_matrices[j].isApprox(bind[j].inverse(), 1e-6)) << "joint " << j;
  }
}

INSTANTIATE_TEST_SUITE_P(ImportGltfEncodings, ImportGltfTest,
                         ::testing::Values(BoxEncoding{kUnsignedByte, kFloat, GltfBuilder::Layout::kExternalBin, "box.gltf"},
                                           BoxEncoding{kUnsignedShort, kUnsignedByte, GltfBuilder::Layout::kDataUri, "box.gltf"},
                                           BoxEncoding{kUnsignedByte, kUnsignedShort, GltfBuilder::Layout::kGlb, "box.glb"}));

TEST(ImportGltfFileTest, NoNormalsGivesEmptyRestNormals) {
  TempDir dir;
  box_document(bent_box(), {kUnsignedByte, kFloat, GltfBuilder::Layout::kDataUri, "box.gltf"}, false)
      .write(dir / "box.gltf", GltfBuilder::Layout::kDataUri);
  auto gltf = read_gltf_rig(dir / "box.gltf");
  ASSERT_TRUE(gltf.ok()) << gltf.error().message;
  EXPECT_EQ(gltf->rest_normals.rows(), 0);
}

struct BrokenGltf {
  const char* name;
  std::function<void(GltfBuilder&)> damage;
  const char* message;  // expected in the error, after the file name
};

class ImportGltfErrorTest : public ::testing::TestWithParam<BrokenGltf> {};

TEST_P(ImportGltfErrorTest, NamesFileAndPart) {
  const BrokenGltf& broken = GetParam();
  TempDir dir;
  GltfBuilder builder = box_document(bent_box(), {kUnsignedByte, kFloat, GltfBuilder::Layout::kDataUri, "box.gltf"});
  broken.damage(builder);
  const auto path = dir / "broken.gltf";
  builder.write(path, GltfBuilder::Layout::kDataUri);
  auto gltf = read_gltf_rig(path);
  ASSERT_FALSE(gltf.ok());
  EXPECT_EQ(gltf.error().code, ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(gltf.error().message, path.string() + ": ")) << gltf.error().message;
  EXPECT_TRUE(contains(gltf.error().message, broken.message)) << gltf.error().message;
}

json& primitive(GltfBuilder& builder) { return builder.doc["meshes"][0]["primitives"][0]; }
json& accessor_of(GltfBuilder& builder, const char* attribute) {
  return builder.doc["accessors"][primitive(builder)["attributes"][attribute].get<int>()];
}

// Overwrites the first joint index of the vertex 5 in the JOINTS_0 data (unsigned bytes).
void set_joint(GltfBuilder& builder, uint8_t joint) {
  const json& view = builder.doc["bufferViews"][accessor_of(builder, "JOINTS_0")["bufferView"].get<int>()];
  builder.bin[view["byteOffset"].get<size_t>() + 4 * 5] = static_cast<char>(joint);
}

void halve_weight(GltfBuilder& builder) {
  const json& view = builder.doc["bufferViews"][accessor_of(builder, "WEIGHTS_0")["bufferView"].get<int>()];
  const size_t at = view["byteOffset"].get<size_t>() + 16 * 6;  // vertex 6, slot 0
  float w;
  std::memcpy(&w, builder.bin.data() + at, 4);
  w -= 0.5f;
  std::memcpy(builder.bin.data() + at, &w, 4);
}

INSTANTIATE_TEST_SUITE_P(
    ImportGltfBroken, ImportGltfErrorTest,
    ::testing::Values(
        BrokenGltf{"MissingPosition", [](GltfBuilder& b) { primitive(b)["attributes"].erase("POSITION"); },
                   "mesh 0 primitive 0 has no POSITION attribute"},
        BrokenGltf{"FloatJoints", [](GltfBuilder& b) { accessor_of(b, "JOINTS_0")["componentType"] = kFloat; },
                   "accessor 2 (JOINTS_0) has component type FLOAT, expected UNSIGNED_BYTE or UNSIGNED_SHORT"},
        BrokenGltf{"JointOutOfRange", [](GltfBuilder& b) { set_joint(b, 7); },
                   "mesh 0 primitive 0: JOINTS_0 of vertex 5 (slot 0) is joint 7, but skin 0 has 3 joints"},
        BrokenGltf{"WeightsDoNotSumToOne", halve_weight, "mesh 0 primitive 0 vertex 6: weights sum to 0.5"},
        BrokenGltf{"AccessorPastItsView", [](GltfBuilder& b) { accessor_of(b, "NORMAL")["count"] = 1000; },
                   "accessor 1 (NORMAL): 1000 elements from byte 0 exceed buffer view 1"},
        BrokenGltf{"WeightsWithoutJoints", [](GltfBuilder& b) { primitive(b)["attributes"].erase("JOINTS_0"); },
                   "mesh 0 primitive 0 has WEIGHTS_0 without JOINTS_0"},
        BrokenGltf{"NotSkinned", [](GltfBuilder& b) { b.doc["nodes"][4].erase("skin"); },
                   "no node has both a mesh and a skin"},
        BrokenGltf{"SingularInverseBind",
                   [](GltfBuilder& b) {
                     const json& view = b.doc["bufferViews"][b.doc["accessors"][5]["bufferView"].get<int>()];
                     std::memset(b.bin.data() + view["byteOffset"].get<size_t>() + 64, 0, 48);  // matrix 1's 3×4
                   },
                   "skin 0: inverseBindMatrices[1] is singular"},
        BrokenGltf{"IndexOutOfRange",
                   [](GltfBuilder& b) {
                     const json& view = b.doc["bufferViews"][primitive(b)["indices"].get<int>()];
                     const uint32_t index = 999;
                     std::memcpy(b.bin.data() + view["byteOffset"].get<size_t>() + 8, &index, 4);
                   },
                   "mesh 0 primitive 0: index 2 is vertex 999"},
        BrokenGltf{"NodeCycle", [](GltfBuilder& b) { b.doc["nodes"][3]["children"] = {0}; }, "is in a cycle of nodes"}),
    [](const ::testing::TestParamInfo<BrokenGltf>& param_info) { return std::string(param_info.param.name); });

TEST(ImportGltfFileTest, MissingAndUnparsableFiles) {
  TempDir dir;
  auto missing = read_gltf_rig(dir / "absent.gltf");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
  testing::write_text_file(dir / "garbage.gltf", "{ \"asset\": [1, 2");
  auto garbage = read_gltf_rig(dir / "garbage.gltf");
  ASSERT_FALSE(garbage.ok());
  EXPECT_EQ(garbage.error().code, ErrorCode::kInvalidArgument);
  EXPECT_TRUE(contains(garbage.error().message, "garbage.gltf: not a readable glTF 2.0 JSON")) << garbage.error().message;
  testing::write_text_file(dir / "truncated.glb", std::string("glTF\x02\0\0\0\xff\0\0\0", 12));
  auto truncated = read_gltf_rig(dir / "truncated.glb");
  ASSERT_FALSE(truncated.ok());
  EXPECT_TRUE(contains(truncated.error().message, "truncated.glb: not a readable glTF 2.0 binary")) << truncated.error().message;
}

}  // namespace
}  // namespace animspace::animation_space
