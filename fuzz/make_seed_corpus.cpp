// Writes the binary seed inputs of fuzz/corpus/ (the text ones are written by hand): tiny model
// containers of every kind the registry loads, a binary PLY, a PC2 cache, a binary DMAT, a miss
// log, the two validated request messages and a skinned glTF strip (.glb, and .gltf with base64
// data URI buffers). Run once and commit the output; rerun when a
// format changes:
//   build-fuzz/bin/make_seed_corpus fuzz/corpus
//
// Everything is built from the demo's bending arm at its smallest (3 rings × 3 segments: 11
// vertices, 3 bones), so that each container stays a few kilobytes: the fuzzer mutates every
// byte of a seed, and small seeds are mutated more.
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <string>
#include <utility>

#include "animspace/v1/poses.pb.h"
#include "animspace/v1/skinning.pb.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/tangents.h"
#include "core/geometry/normals.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/lod/levels.h"
#include "core/lod/lod_io.h"
#include "core/lod/simplify.h"
#include "core/mesh_io/pc2.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "core/misslog/miss_log.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/train.h"
#include "fuzz/request_fixture.h"
#include "harness/gltf_builder.h"
#include "harness/lod_fixtures.h"

namespace animspace::fuzz {
namespace {

namespace fs = std::filesystem;

constexpr int kRings = 3;
constexpr int kSegments = 3;
constexpr int kFrames = 12;

// Exits on a failed step: a seed generator has nothing to recover.
template <typename T>
T need(Result<T> result, const char* what) {
  if (!result.ok()) {
    std::fprintf(stderr, "make_seed_corpus: %s: %s\n", what, result.error().message.c_str());
    std::exit(1);
  }
  return std::move(result).value();
}

void need(const Status& status, const char* what) {
  if (!status.ok()) {
    std::fprintf(stderr, "make_seed_corpus: %s: %s\n", what, status.error().message.c_str());
    std::exit(1);
  }
}

void write(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
  std::printf("%6zu bytes  %s\n", bytes.size(), path.c_str());
}

template <typename T>
void append_big_endian(std::string& out, T value) {
  char bytes[sizeof value];
  std::memcpy(bytes, &value, sizeof value);
  for (size_t i = sizeof value; i > 0; --i) out += bytes[i - 1];
}

// A triangle in binary big-endian PLY with float64 coordinates and uint indices: the other byte
// order and other numeric types than serialize_ply writes.
std::string big_endian_ply() {
  std::string out =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
      "property double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
  for (const double value : {0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0}) append_big_endian(out, value);
  out += static_cast<char>(3);
  for (const uint32_t index : {0u, 1u, 2u}) append_big_endian(out, index);
  return out;
}

demo::BendingArmOptions tiny_arm() {
  demo::BendingArmOptions options;
  options.rings = kRings;
  options.segments = kSegments;
  return options;
}

// The arm in animation space with tangent planes, metrics and LOD levels: every section
// animation_space::load and lod::load_levels read.
container::ModelContainer animation_space_container(animation_space::AnimationSpaceModel* engine) {
  testing::LodCase arm = testing::arm_lod_case(kRings, kSegments, kFrames);
  const auto rest = animation_space::rest_positions(arm.model);
  const auto planes = need(animation_space::tangent_planes_from_normals(
                               arm.model, geometry::area_weighted_normals(rest, arm.model.faces)),
                           "tangent planes");
  arm.model.tangent_s = planes.s;
  arm.model.tangent_t = planes.t;
  const auto progressive = need(lod::build_progressive_mesh(arm.model, arm.metrics), "progressive mesh");
  container::ModelContainer c;
  animation_space::store(arm.model, c);
  animation_space::store_metrics(need(animation_space::stored_metrics_from_poses(arm.model, arm.poses), "metrics"), c);
  lod::store_levels(lod::make_levels(progressive, 3), c);
  *engine = arm.model;
  return c;
}

// PMSC trained on the expensive rig's frames of the same arm.
container::ModelContainer pmsc_container() {
  const demo::ArmRig rig = demo::make_arm_rig(tiny_arm());
  FrameMatrix frames(kFrames, 3 * rig.rest.V.rows());
  int f = 0;
  for (const demo::ArmPose& pose : demo::demo_animation(kFrames)) {
    const PointMatrix points = demo::pose_expensive(pose, rig);
    frames.row(f++) = Eigen::Map<const Eigen::RowVectorXf>(points.data(), points.size());
  }
  const Eigen::VectorXf rest = Eigen::Map<const Eigen::VectorXf>(rig.rest.V.data(), rig.rest.V.size());
  pmsc::TrainingOptions options;
  options.error_bound = 0.01 * pmsc::bounding_box_diagonal(rest);
  options.error_tolerance = 0.02 * pmsc::bounding_box_diagonal(rest);
  options.basis_size = 4;
  options.calibration_folds = 3;
  options.region_count = 2;
  pmsc::TrainingReport report;
  const auto model = need(pmsc::train(frames, options, &report), "pmsc training");
  auto c = pmsc::make_container(rig.rest, frames, nullptr, model, report, "fuzz seed: tiny arm");
  pmsc::store_training_options(options, c);
  return c;
}

std::string miss_log_bytes(const fs::path& scratch) {
  fs::remove(scratch);
  {
    auto log = need(misslog::MissLog::open(scratch, misslog::FsyncPolicy::kNever, std::chrono::milliseconds(0)),
                    "miss log");
    misslog::MissRecord blend;
    blend.status = pmsc::CacheStatus::kBlend;
    blend.key_point_error = 0.5;
    blend.blend_weight = 0.25;
    blend.key_values = {1, 2, 3, 4, 5, 6};
    need(log->append(blend), "miss record");
    misslog::MissRecord miss = blend;
    miss.status = pmsc::CacheStatus::kMiss;
    miss.full_values = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    need(log->append(miss), "miss record");
  }
  std::ifstream in(scratch, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  fs::remove(scratch);
  return bytes;
}

// The rest pose of request_fixture::skeleton() as the request carries it: global transforms G_j,
// or local ones L_j = G_parent⁻¹ G_j; 12 float32 per bone.
v1::SkeletonPose skeleton_pose(v1::SkeletonPose::Space space) {
  const animation_space::Skeleton skeleton = request_fixture::skeleton();
  const animation_space::TransformList transforms = space == v1::SkeletonPose::SPACE_LOCAL
                                                        ? animation_space::joint_transforms(skeleton, skeleton.rest)
                                                        : skeleton.rest;
  v1::SkeletonPose pose;
  pose.set_space(space);
  pose.set_bone_count(static_cast<uint32_t>(transforms.size()));
  std::string bytes;
  for (const animation_space::Transform& T : transforms) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        const auto value = static_cast<float>(T(r, c));
        bytes.append(reinterpret_cast<const char*>(&value), sizeof value);
      }
    }
  }
  pose.set_transforms(bytes);
  return pose;
}

std::string with_selector(request_fixture::Selector selector, const google::protobuf::Message& message) {
  return std::string(1, static_cast<char>(selector)) + message.SerializeAsString();
}

void write_requests(const fs::path& dir) {
  v1::EvaluateKeyPointsRequest key_points;
  key_points.mutable_model()->set_name("arm-pmsc");
  for (int i = 0; i < 2; ++i) {
    v1::KeyPointPose* pose = key_points.add_poses();
    std::string values;
    for (uint32_t k = 0; k < request_fixture::kKeyPoints * request_fixture::kChannels; ++k) {
      const auto value = static_cast<float>(k);
      values.append(reinterpret_cast<const char*>(&value), sizeof value);
    }
    pose->mutable_key_values()->set_point_count(request_fixture::kKeyPoints);
    pose->mutable_key_values()->set_channel_count(request_fixture::kChannels);
    pose->mutable_key_values()->set_data(values);
    if (i == 1) *pose->mutable_skeleton_pose() = skeleton_pose(v1::SkeletonPose::SPACE_GLOBAL);
  }
  write(dir / "key_points.bin", with_selector(request_fixture::kKeyPointsRequest, key_points));

  v1::EvaluateSkeletonPoseRequest skinning;
  skinning.mutable_model()->set_name("arm-animspace");
  skinning.mutable_model()->set_version(1);
  *skinning.add_poses() = skeleton_pose(v1::SkeletonPose::SPACE_LOCAL);
  *skinning.add_poses() = skeleton_pose(v1::SkeletonPose::SPACE_GLOBAL);
  write(dir / "skeleton_pose.bin", with_selector(request_fixture::kSkeletonPoseRequest, skinning));
}

// A strip of 4 triangles along x (6 vertices, x = 0, 1, 2) skinned to a chain of two joints
// (root at x = 0, child at x = 1, bent in the file's pose), the smallest rig that still has a
// parent, an inverse bind matrix other than identity and blended weights. The encodings vary
// across seeds so that each accessor path of the importer has a seed that reaches it.
struct StripEncoding {
  int joint_type;     // 5121 UNSIGNED_BYTE or 5123 UNSIGNED_SHORT
  int weight_type;    // 5126 FLOAT, or 5121 / 5123 normalised
  int index_type;     // 5121, 5123, 5125, or 0 for no indices (consecutive triangles; 12 vertices)
  bool normals;       // a NORMAL attribute
  bool matrix_nodes;  // node transforms as "matrix" instead of TRS
};

std::string skinned_strip(const StripEncoding& e, testing::GltfBuilder::Layout layout) {
  constexpr int kByte = 5121, kShort = 5123, kInt = 5125, kFloat = 5126;
  std::vector<std::array<float, 3>> corners;
  for (int x = 0; x <= 2; ++x) {
    for (int y = 0; y <= 1; ++y) corners.push_back({static_cast<float>(x), static_cast<float>(y), 0.0f});
  }
  const std::vector<uint32_t> triangles{0, 2, 1, 1, 2, 3, 2, 4, 3, 3, 4, 5};
  // Without indices the triangles' corners are listed one after another.
  std::vector<std::array<float, 3>> vertices = corners;
  if (e.index_type == 0) {
    vertices.clear();
    for (const uint32_t corner : triangles) vertices.push_back(corners[corner]);
  }
  const size_t n = vertices.size();
  std::vector<float> positions, normals, weights;
  std::vector<uint16_t> joints;
  for (const auto& v : vertices) {
    positions.insert(positions.end(), v.begin(), v.end());
    normals.insert(normals.end(), {0.0f, 0.0f, 1.0f});
    const float t = v[0] / 2;  // the child's share grows along the strip
    joints.insert(joints.end(), {0, 1, 0, 0});
    weights.insert(weights.end(), {1 - t, t, 0.0f, 0.0f});
  }
  testing::GltfBuilder b;
  nlohmann::json attributes = {{"POSITION", b.add(positions, kFloat, "VEC3", n)}};
  if (e.normals) attributes["NORMAL"] = b.add(normals, kFloat, "VEC3", n);
  attributes["JOINTS_0"] = e.joint_type == kByte
                               ? b.add(std::vector<uint8_t>(joints.begin(), joints.end()), kByte, "VEC4", n)
                               : b.add(joints, kShort, "VEC4", n);
  if (e.weight_type == kFloat) {
    attributes["WEIGHTS_0"] = b.add(weights, kFloat, "VEC4", n);
  } else {
    // Normalised integers, the rounding remainder on the first slot so that each vertex sums to max.
    const double max = e.weight_type == kByte ? 255.0 : 65535.0;
    std::vector<uint16_t> quantised;
    for (size_t v = 0; v < n; ++v) {
      const auto child = static_cast<uint16_t>(std::lround(weights[4 * v + 1] * max));
      quantised.insert(quantised.end(), {static_cast<uint16_t>(max - child), child, 0, 0});
    }
    attributes["WEIGHTS_0"] =
        e.weight_type == kByte ? b.add(std::vector<uint8_t>(quantised.begin(), quantised.end()), kByte, "VEC4", n, true)
                               : b.add(quantised, kShort, "VEC4", n, true);
  }
  nlohmann::json primitive = {{"attributes", attributes}, {"mode", 4}};
  const size_t corner_count = triangles.size();
  if (e.index_type == kByte) {
    const std::vector<uint8_t> narrow(triangles.begin(), triangles.end());
    primitive["indices"] = b.add(narrow, kByte, "SCALAR", corner_count);
  } else if (e.index_type == kShort) {
    const std::vector<uint16_t> narrow(triangles.begin(), triangles.end());
    primitive["indices"] = b.add(narrow, kShort, "SCALAR", corner_count);
  } else if (e.index_type == kInt) {
    primitive["indices"] = b.add(triangles, kInt, "SCALAR", corner_count);
  }
  // Bind pose: root at the origin, child at x = 1, so inverse binds are I and a −1 x translation
  // (column-major).
  std::vector<float> inverse_binds{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
                                   1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1};
  const int ibm = b.add(inverse_binds, kFloat, "MAT4", 2);
  b.doc["meshes"] = {{{"primitives", {primitive}}}};
  // The child turned 30° about z: (x y z w) = (0 0 sin 15° cos 15°).
  const double s = std::sin(std::numbers::pi / 12), c = std::cos(std::numbers::pi / 12);
  nlohmann::json root = {{"name", "root"}, {"children", {1}}};
  nlohmann::json child = {{"name", "child"}};
  if (e.matrix_nodes) {
    const double cos30 = c * c - s * s, sin30 = 2 * s * c;
    child["matrix"] = {cos30, sin30, 0, 0, -sin30, cos30, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1};
  } else {
    child["translation"] = {1.0, 0.0, 0.0};
    child["rotation"] = {0.0, 0.0, s, c};
  }
  b.doc["nodes"] = {root, child, {{"mesh", 0}, {"skin", 0}}};
  b.doc["skins"] = {{{"joints", {0, 1}}, {"inverseBindMatrices", ibm}}};
  b.doc["scenes"] = {{{"nodes", {0, 2}}}};
  b.doc["scene"] = 0;
  return b.serialize(layout);
}

}  // namespace
}  // namespace animspace::fuzz

int main(int argc, char** argv) {
  using namespace animspace;
  using namespace animspace::fuzz;
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <corpus directory, e.g. fuzz/corpus>\n", argv[0]);
    return 2;
  }
  const fs::path corpus = argv[1];

  // model_container: every kind, and a PMSC model with a posing engine (fail-through "server").
  animation_space::AnimationSpaceModel engine;
  const container::ModelContainer animspace_model = animation_space_container(&engine);
  const container::ModelContainer pmsc = pmsc_container();
  container::ModelContainer pmsc_engine = pmsc;
  need(pmsc::attach_posing_engine(engine, pmsc_engine), "posing engine");
  write(corpus / "model_container" / "mesh_sequence.anim",
        container::serialize(demo::make_demo_container(tiny_arm(), 2)));
  write(corpus / "model_container" / "animation_space.anim", container::serialize(animspace_model));
  write(corpus / "model_container" / "pmsc.anim", container::serialize(pmsc));
  write(corpus / "model_container" / "pmsc_engine.anim", container::serialize(pmsc_engine));

  // One quad: binary PLY and PC2 (the text formats are hand-written seeds).
  TriangleMesh quad;
  quad.V.resize(4, 3);
  quad.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  quad.F.resize(2, 3);
  quad.F << 0, 1, 2, 0, 2, 3;
  write(corpus / "ply" / "quad_binary_le.ply", mesh_io::serialize_ply(quad));
  write(corpus / "ply" / "triangle_binary_be.ply", big_endian_ply());
  mesh_io::PointCache cache;
  cache.num_points = 4;
  cache.samples.resize(2, 12);
  cache.samples.row(0) = Eigen::Map<const Eigen::RowVectorXf>(quad.V.data(), 12);
  cache.samples.row(1) = cache.samples.row(0).array() + 0.5f;
  write(corpus / "pc2" / "quad_two_frames.pc2", mesh_io::serialize_pc2(cache));

  // Binary DMAT: `0 0`, then `cols rows`, then column-major float64 (2 × 3 here).
  std::string dmat = "0 0\n3 2\n";
  for (const double value : {1.0, 0.0, 0.5, 0.5, 0.0, 1.0}) {
    dmat.append(reinterpret_cast<const char*>(&value), sizeof value);
  }
  write(corpus / "dmat" / "binary.dmat", dmat);

  write(corpus / "miss_log" / "two_records.misses",
        miss_log_bytes(fs::temp_directory_path() / "make_seed_corpus.misses"));
  write_requests(corpus / "request_validation");

  // gltf: the framings (GLB chunks, JSON with a data URI) and the accessor encodings.
  using Layout = testing::GltfBuilder::Layout;
  write(corpus / "gltf" / "skinned_strip.glb", skinned_strip({5121, 5126, 5123, true, false}, Layout::kGlb));
  write(corpus / "gltf" / "skinned_strip_embedded.gltf",
        skinned_strip({5123, 5121, 5125, true, false}, Layout::kDataUri));
  write(corpus / "gltf" / "skinned_strip_matrices_no_indices.gltf",
        skinned_strip({5121, 5123, 0, false, true}, Layout::kDataUri));
  write(corpus / "gltf" / "skinned_strip_byte_indices.glb",
        skinned_strip({5123, 5126, 5121, false, false}, Layout::kGlb));
  return 0;
}
