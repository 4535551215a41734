// Issue #7, levels of detail for render farms, over real gRPC against the real animspaced:
// LodService.GetLod sends the core's level byte for byte (animation-space form) or posed exactly
// as animation_space::evaluate poses it; chunked streams reassemble to the same mesh whatever the
// block size; pixel tolerance and budget choose the levels lod::level_for_view and a plain scan
// choose here; bad requests get the exact status naming the proto field; `animspace lod` writes a
// glTF that tinygltf loads back. Expected values come from the core, loaded here from the same
// model file, never from the daemon.
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "animspace/v1/lod.grpc.pb.h"
#include "clients/cpp/client.h"
#include "core/animspace/animspace_io.h"
#include "core/animspace/model.h"
#include "core/atlas/atlas_io.h"
#include "core/container/model_container.h"
#include "core/demo/demo_repository.h"
#include "core/lod/levels.h"
#include "core/lod/lod_io.h"
#include "core/lod/selection.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "core/container/sections.h"
#include "harness/build_tree.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "harness/lod_fixtures.h"
#include "tests/support/test_support.h"

#include "tests/support/tiny_gltf.h"

namespace animspace {
namespace {

namespace as = animation_space;
using harness::DaemonProcess;
using testing::TempDir;
using Form = v1::GetLodRequest::Form;

constexpr const char* kModel = "arm-animspace";

template <typename T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
  // memcmp must not see the null data() of an empty vector, even with a zero size.
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// What the core holds for one level, in the wire's types (float32 positions, uint32 indices).
struct ExpectedLevel {
  std::vector<uint32_t> offsets;
  std::vector<uint32_t> bones;
  std::vector<float> positions;  // 4 per influence
  std::vector<float> delta;      // 4 per influence (geomorph)
  std::vector<uint32_t> faces;
};

std::vector<uint32_t> as_u32(const std::vector<int32_t>& values) { return {values.begin(), values.end()}; }

std::vector<float> as_f32(const as::InfluenceVectors& vectors) {
  std::vector<float> out(static_cast<size_t>(vectors.size()));
  for (size_t i = 0; i < out.size(); ++i) out[i] = static_cast<float>(vectors.data()[i]);  // column-major: 4 per influence
  return out;
}

std::vector<uint32_t> faces_u32(const FaceMatrix& faces) {
  return {faces.data(), faces.data() + faces.size()};  // row-major: 3 per face
}

std::vector<float> points_f32(const PointMatrix& points) { return {points.data(), points.data() + points.size()}; }

// A pose with float32 entries (what the wire carries), so the daemon and the test evaluate the
// same doubles.
as::TransformList float_rounded(const as::TransformList& globals) {
  as::TransformList out = globals;
  for (auto& G : out) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) G(r, c) = static_cast<double>(static_cast<float>(G(r, c)));
    }
  }
  return out;
}

v1::GetLodRequest level_request(uint32_t level, Form form, const std::string& model = kModel) {
  v1::GetLodRequest request;
  request.mutable_model()->set_name(model);
  request.set_level(level);
  request.set_form(form);
  return request;
}

// The whole stream through the generated stub, chunk by chunk, with its status.
struct RawStream {
  std::vector<v1::LodChunk> chunks;
  grpc::Status status;
};

RawStream raw_stream(const std::shared_ptr<grpc::Channel>& channel, const v1::GetLodRequest& request) {
  auto stub = v1::LodService::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto reader = stub->GetLod(&context, request);
  RawStream out;
  v1::LodChunk chunk;
  while (reader->Read(&chunk)) out.chunks.push_back(chunk);
  out.status = reader->Finish();
  return out;
}

void expect_same_mesh(const LodMesh& a, const LodMesh& b) {
  EXPECT_EQ(a.header.SerializeAsString(), b.header.SerializeAsString());
  EXPECT_TRUE(same_bytes(a.positions, b.positions));
  EXPECT_TRUE(same_bytes(a.influence_offsets, b.influence_offsets));
  EXPECT_TRUE(same_bytes(a.bone_indices, b.bone_indices));
  EXPECT_TRUE(same_bytes(a.animation_positions, b.animation_positions));
  EXPECT_TRUE(same_bytes(a.geomorph_delta, b.geomorph_delta));
  EXPECT_TRUE(same_bytes(a.indices, b.indices));
  EXPECT_EQ(a.skeleton.SerializeAsString(), b.skeleton.SerializeAsString());
}

// Runs the command line; returns its stdout, and its stderr in `errors` (gRPC may log there).
std::string run_cli(const std::string& arguments, int* exit_code, std::string* errors = nullptr) {
  TempDir scratch;
  const auto stderr_path = scratch / "stderr.txt";
  const std::string command = harness::program_path("animspace").string() + " " + arguments + " 2> " + stderr_path.string();
  FILE* pipe = popen(command.c_str(), "r");
  std::string out;
  if (pipe == nullptr) {
    *exit_code = -1;
    return out;
  }
  std::array<char, 4096> buffer{};
  while (size_t n = std::fread(buffer.data(), 1, buffer.size(), pipe)) out.append(buffer.data(), n);
  const int status = pclose(pipe);
  *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (errors != nullptr) {
    std::ifstream file(stderr_path);
    errors->assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  }
  return out;
}

class LodServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    work_ = new TempDir();
    repo_ = work_->path() / "repo";
    ASSERT_TRUE(testing::write_demo_repository(repo_).ok());
    // A large flat sheet (one bone, one level): a stream of many blocks.
    sheet_ = new as::AnimationSpaceModel(testing::flat_sheet_case(kSheetSize).model);
    container::ModelContainer sheet;
    as::store(*sheet_, sheet);
    testing::write_model(repo_, "sheet", 1, sheet);
    // The demo arm with an atlas (issue #37): per-corner UVs made up here, a different UV for
    // every corner, so each shared vertex is a seam; one chart (load_atlas wants them dense).
    {
      auto arm = container::read_file(repo_ / kModel / "1" / "model.anim");
      ASSERT_TRUE(arm.ok()) << arm.error().message;
      auto faces = arm->int_matrix(container::sections::kFaces, 3);
      ASSERT_TRUE(faces.ok()) << faces.error().message;
      atlas_ = new atlas::Atlas();
      const Eigen::Index F = faces->rows();
      atlas_->chart_count = 1;
      atlas_->chart_of_face.assign(static_cast<size_t>(F), 0);
      atlas_->uvs.resize(3 * F, 2);
      for (Eigen::Index r = 0; r < 3 * F; ++r) {
        atlas_->uvs(r, 0) = static_cast<double>(r) / static_cast<double>(3 * F);
        atlas_->uvs(r, 1) = 0.5 + 0.45 * std::sin(0.37 * static_cast<double>(r));
      }
      atlas::store_atlas(*atlas_, "rest_pose", *arm);
      testing::write_model(repo_, kAtlasModel, 1, *arm);
    }
    daemon_ = new DaemonProcess({"--model-repository", repo_.string(), "--log-level", "info"}, work_->path());
    client_ = new Client(daemon_->address());
    ASSERT_TRUE(testing::wait_until_serving(*client_)) << "never SERVING";

    // The core's levels of the served model, read from the same file the daemon loaded.
    auto in = container::read_file(repo_ / kModel / "1" / "model.anim");
    ASSERT_TRUE(in.ok()) << in.error().message;
    container_ = new container::ModelContainer(std::move(*in));
    auto model = as::load(*container_, kModel);
    ASSERT_TRUE(model.ok()) << model.error().message;
    model_ = new as::AnimationSpaceModel(std::move(*model));
    auto levels = lod::load_levels(*container_, *model_, kModel);
    ASSERT_TRUE(levels.ok()) << levels.error().message;
    levels_ = new lod::LodLevels(std::move(*levels));
    ASSERT_GE(levels_->count(), 4) << "the demo's arm-animspace is expected to carry several levels";
    auto sphere = lod::model_bounding_sphere(*container_, *model_, kModel);
    ASSERT_TRUE(sphere.ok());
    radius_ = sphere->radius;
  }
  static void TearDownTestSuite() {
    delete client_;
    delete daemon_;
    delete levels_;
    delete model_;
    delete container_;
    delete sheet_;
    delete atlas_;
    delete work_;
    client_ = nullptr;
    daemon_ = nullptr;
    levels_ = nullptr;
    model_ = nullptr;
    container_ = nullptr;
    sheet_ = nullptr;
    atlas_ = nullptr;
    work_ = nullptr;
  }

  static std::shared_ptr<grpc::Channel> channel() { return client_->channel(); }
  static const lod::LodLevel& level(int l) { return levels_->levels[static_cast<size_t>(l)]; }

  static ExpectedLevel expected(int l) {
    const as::AnimationSpaceModel& m = level(l).model;
    return {as_u32(m.influences.offsets), as_u32(m.influences.bones), as_f32(m.positions), {}, faces_u32(m.faces)};
  }

  // A stored training pose of the model (sequence.bone_transforms), float-rounded.
  static as::TransformList stored_pose(int frame) {
    auto rows = container_->double_matrix(container::sections::kSequenceBoneTransforms, 16 * model_->bone_count());
    EXPECT_TRUE(rows.ok());
    return float_rounded(as::pose_from_row(*rows, frame, model_->bone_count()));
  }

  static v1::GetLodRequest view_request(float tolerance_px, float distance, float fov_rad = 0.8f,
                                        uint32_t width = 1920) {
    v1::GetLodRequest request;
    request.mutable_model()->set_name(kModel);
    request.set_form(v1::GetLodRequest::FORM_POSED);
    auto* view = request.mutable_pixel_tolerance();
    view->set_tolerance_px(tolerance_px);
    view->set_distance(distance);
    view->set_horizontal_fov_rad(fov_rad);
    view->set_viewport_width_px(width);
    return request;
  }

  static inline TempDir* work_ = nullptr;
  static inline std::filesystem::path repo_;
  static inline DaemonProcess* daemon_ = nullptr;
  static inline Client* client_ = nullptr;
  static inline container::ModelContainer* container_ = nullptr;
  static inline as::AnimationSpaceModel* model_ = nullptr;
  static inline lod::LodLevels* levels_ = nullptr;
  static inline double radius_ = 0;
  static constexpr int kSheetSize = 400;  // 401² vertices, 2·400² faces
  static inline as::AnimationSpaceModel* sheet_ = nullptr;
  static constexpr const char* kAtlasModel = "arm-atlas";  // arm-animspace with atlas_
  static inline atlas::Atlas* atlas_ = nullptr;
};

// ---------------------------------------------------------------------------------------------
// The animation-space form is the core's level, byte for byte.

TEST_F(LodServiceTest, AnimationSpaceFormByteEqualsTheCoresLevel) {
  for (int l : {0, 3, levels_->count() - 1}) {
    SCOPED_TRACE("level " + std::to_string(l));
    const LodMesh mesh = client_->get_lod(level_request(static_cast<uint32_t>(l), v1::GetLodRequest::FORM_ANIMATION_SPACE));
    const lod::LodLevel& core = level(l);
    const ExpectedLevel want = expected(l);
    const v1::LodHeader& h = mesh.header;
    EXPECT_EQ(h.model_version(), 1u);
    EXPECT_EQ(h.level(), static_cast<uint32_t>(l));
    EXPECT_EQ(h.level_count(), static_cast<uint32_t>(levels_->count()));
    EXPECT_EQ(h.epsilon(), static_cast<float>(core.epsilon));
    EXPECT_EQ(h.vertex_count(), static_cast<uint32_t>(core.model.vertex_count()));
    EXPECT_EQ(h.face_count(), static_cast<uint32_t>(core.model.faces.rows()));
    EXPECT_EQ(h.bone_count(), static_cast<uint32_t>(core.model.bone_count()));
    EXPECT_EQ(h.influence_count(), static_cast<uint32_t>(core.model.influences.influence_count()));
    EXPECT_EQ(h.form(), v1::GetLodRequest::FORM_ANIMATION_SPACE);
    EXPECT_EQ(h.tolerated_error(), 0.0f);

    EXPECT_TRUE(same_bytes(mesh.influence_offsets, want.offsets));
    EXPECT_TRUE(same_bytes(mesh.bone_indices, want.bones));
    EXPECT_TRUE(same_bytes(mesh.animation_positions, want.positions));
    EXPECT_TRUE(same_bytes(mesh.indices, want.faces));
    EXPECT_TRUE(mesh.positions.empty());
    EXPECT_TRUE(mesh.geomorph_delta.empty());

    // The skeleton: parents, Ĝ_j in SkeletonPose.transforms layout, names.
    const as::Skeleton& skeleton = core.model.skeleton;
    ASSERT_EQ(mesh.skeleton.parents_size(), skeleton.bone_count());
    std::vector<float> rest;
    for (int j = 0; j < skeleton.bone_count(); ++j) {
      EXPECT_EQ(mesh.skeleton.parents(j), skeleton.parents[static_cast<size_t>(j)]);
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) rest.push_back(static_cast<float>(skeleton.rest[static_cast<size_t>(j)](r, c)));
      }
    }
    ASSERT_EQ(mesh.skeleton.rest_transforms().size(), rest.size() * sizeof(float));
    EXPECT_EQ(std::memcmp(mesh.skeleton.rest_transforms().data(), rest.data(), rest.size() * sizeof(float)), 0);
    ASSERT_EQ(static_cast<size_t>(mesh.skeleton.bone_names_size()), skeleton.names.size());
    for (size_t j = 0; j < skeleton.names.size(); ++j) EXPECT_EQ(mesh.skeleton.bone_names(static_cast<int>(j)), skeleton.names[j]);
  }
}

// ---------------------------------------------------------------------------------------------
// The posed form is animation_space::evaluate of the level, exactly: the daemon decodes the same
// float32 transforms into the same doubles and runs the same evaluator on the same level.

TEST_F(LodServiceTest, PosedFormEqualsTheCoresEvaluation) {
  const as::TransformList pose = stored_pose(7);
  for (int l : {0, 2, levels_->count() - 1}) {
    SCOPED_TRACE("level " + std::to_string(l));
    const as::AnimationSpaceModel& core = level(l).model;
    PointMatrix want;

    // The rest pose when no pose is sent.
    LodMesh rest = client_->get_lod(level_request(static_cast<uint32_t>(l), v1::GetLodRequest::FORM_POSED));
    as::evaluate(core, core.skeleton.rest, want);
    EXPECT_EQ(rest.header.form(), v1::GetLodRequest::FORM_POSED);
    EXPECT_EQ(rest.header.influence_count(), 0u);
    EXPECT_TRUE(same_bytes(rest.positions, points_f32(want)));
    EXPECT_TRUE(same_bytes(rest.indices, faces_u32(core.faces)));
    EXPECT_TRUE(rest.influence_offsets.empty());
    EXPECT_EQ(rest.skeleton.parents_size(), 0);

    v1::GetLodRequest request = level_request(static_cast<uint32_t>(l), v1::GetLodRequest::FORM_POSED);
    *request.mutable_pose() = testing::global_skeleton_pose(pose);
    LodMesh posed = client_->get_lod(request);
    as::evaluate(core, pose, want);
    EXPECT_TRUE(same_bytes(posed.positions, points_f32(want)));
    EXPECT_FALSE(same_bytes(posed.positions, rest.positions)) << "the pose should move the mesh";
  }
}

// ---------------------------------------------------------------------------------------------
// Chunking: small blocks reassemble to exactly the single-block mesh.

TEST_F(LodServiceTest, SmallChunksReassembleExactly) {
  const int l = 1;
  const auto V = static_cast<uint32_t>(level(l).model.vertex_count());
  const auto F = static_cast<uint32_t>(level(l).model.faces.rows());
  struct Variant {
    Form form;
    bool geomorph;
  };
  for (const Variant& variant : {Variant{v1::GetLodRequest::FORM_ANIMATION_SPACE, false},
                                 Variant{v1::GetLodRequest::FORM_ANIMATION_SPACE, true},
                                 Variant{v1::GetLodRequest::FORM_POSED, false}}) {
    SCOPED_TRACE(std::string(v1::GetLodRequest::Form_Name(variant.form)) + (variant.geomorph ? " + geomorph" : ""));
    v1::GetLodRequest request = level_request(l, variant.form);
    request.set_include_geomorph(variant.geomorph);
    if (variant.form == v1::GetLodRequest::FORM_POSED) *request.mutable_pose() = testing::global_skeleton_pose(stored_pose(3));

    request.set_vertices_per_chunk(1u << 20);
    const LodMesh whole = client_->get_lod(request);
    request.set_vertices_per_chunk(7);
    const LodMesh pieces = client_->get_lod(request);
    expect_same_mesh(whole, pieces);

    // The blocks themselves: in order, contiguous, at most 7 vertices or faces each.
    const RawStream raw = raw_stream(channel(), request);
    ASSERT_TRUE(raw.status.ok()) << raw.status.error_message();
    ASSERT_FALSE(raw.chunks.empty());
    EXPECT_TRUE(raw.chunks.front().has_header());
    uint32_t vertex_blocks = 0, face_blocks = 0, next_vertex = 0, next_face = 0;
    for (const auto& chunk : raw.chunks) {
      if (chunk.has_vertices()) {
        EXPECT_EQ(chunk.vertices().first_vertex(), next_vertex);
        EXPECT_GE(chunk.vertices().vertex_count(), 1u);
        EXPECT_LE(chunk.vertices().vertex_count(), 7u);
        next_vertex += chunk.vertices().vertex_count();
        ++vertex_blocks;
      } else if (chunk.has_faces()) {
        EXPECT_EQ(next_vertex, V) << "faces after every vertex";
        EXPECT_EQ(chunk.faces().first_face(), next_face);
        EXPECT_LE(chunk.faces().face_count(), 7u);
        next_face += chunk.faces().face_count();
        ++face_blocks;
      }
    }
    EXPECT_EQ(vertex_blocks, (V + 6) / 7);
    EXPECT_EQ(face_blocks, (F + 6) / 7);
    const bool skeleton_last = raw.chunks.back().has_skeleton();
    EXPECT_EQ(skeleton_last, variant.form == v1::GetLodRequest::FORM_ANIMATION_SPACE);
    EXPECT_EQ(pieces.chunk_count, raw.chunks.size());
  }
}

// A server with a small message limit cuts blocks by bytes, not only by vertex count.
TEST_F(LodServiceTest, BlocksStayUnderTheServersMessageLimit) {
  TempDir work;
  constexpr int64_t kLimit = 4096;
  DaemonProcess small({"--model-repository", repo_.string(), "--max-message-bytes", std::to_string(kLimit)},
                      work.path());
  Client client(small.address());
  ASSERT_TRUE(testing::wait_until_serving(client));
  for (bool geomorph : {false, true}) {
    v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_ANIMATION_SPACE);
    request.set_include_geomorph(geomorph);
    const RawStream raw = raw_stream(client.channel(), request);
    ASSERT_TRUE(raw.status.ok()) << raw.status.error_message();
    EXPECT_GT(raw.chunks.size(), 10u);
    for (const auto& chunk : raw.chunks) EXPECT_LE(chunk.ByteSizeLong(), static_cast<size_t>(kLimit));
    expect_same_mesh(client.get_lod(request), client_->get_lod(request));
  }
}

// A chunk that cannot be made small enough — one vertex's influences, or the whole skeleton, over
// the message limit — ends the stream with RESOURCE_EXHAUSTED naming the limit, and nothing else
// breaks: a 40-bone rig whose 3 vertices each have all 40 bones, behind a 1024-byte limit.
TEST_F(LodServiceTest, ChunksOverTheMessageLimitAreRefused) {
  TempDir work;
  constexpr int kBones = 40;
  as::AnimationSpaceModel wide;
  for (int j = 0; j < kBones; ++j) wide.skeleton.parents.push_back(j - 1);
  wide.skeleton.rest.assign(kBones, as::Transform::Identity());
  const Eigen::Matrix3d corners = Eigen::Matrix3d::Identity();
  wide.positions.resize(4, 3 * kBones);
  for (int v = 0; v < 3; ++v) {
    for (int j = 0; j < kBones; ++j) {
      wide.influences.bones.push_back(j);
      wide.positions.col(v * kBones + j) << corners.col(v) / kBones, 1.0 / kBones;  // Σ_j p_j = (corner, 1)
    }
    wide.influences.offsets.push_back(static_cast<int32_t>(wide.influences.bones.size()));
  }
  wide.faces.resize(1, 3);
  wide.faces << 0, 1, 2;
  ASSERT_TRUE(as::validate(wide).ok());
  container::ModelContainer stored;
  as::store(wide, stored);
  testing::write_model(work.path() / "repo", "wide", 1, stored);
  DaemonProcess small({"--model-repository", (work.path() / "repo").string(), "--max-message-bytes", "1024"},
                      work.path());
  Client client(small.address());
  ASSERT_TRUE(testing::wait_until_serving(client));

  // Posed, the mesh is 3 points: fine.
  EXPECT_EQ(client.get_lod(level_request(0, v1::GetLodRequest::FORM_POSED, "wide")).positions.size(), 9u);
  // Animation space: each vertex fits alone (40 × 20 bytes), the skeleton (40 × 48 bytes) does not.
  RawStream raw = raw_stream(client.channel(), level_request(0, v1::GetLodRequest::FORM_ANIMATION_SPACE, "wide"));
  EXPECT_EQ(raw.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(raw.status.error_message().find("the chunk carrying the skeleton would be"), std::string::npos)
      << raw.status.error_message();
  EXPECT_NE(raw.status.error_message().find("the limit is 1024 (--max-message-bytes)"), std::string::npos)
      << raw.status.error_message();
  EXPECT_EQ(raw.chunks.size(), 5u) << "header, 3 one-vertex blocks, 1 face block";
  // With Δp a vertex needs 40 × 36 bytes: the first vertex block is refused.
  v1::GetLodRequest morph = level_request(0, v1::GetLodRequest::FORM_ANIMATION_SPACE, "wide");
  morph.set_include_geomorph(true);
  raw = raw_stream(client.channel(), morph);
  EXPECT_EQ(raw.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(raw.status.error_message().find("the chunk carrying vertex 0 would be"), std::string::npos)
      << raw.status.error_message();
  EXPECT_EQ(raw.chunks.size(), 1u) << "the header only";
  EXPECT_EQ(client.get_lod(level_request(0, v1::GetLodRequest::FORM_POSED, "wide")).header.vertex_count(), 3u);
}

// ---------------------------------------------------------------------------------------------
// Geomorph data (§7.3): the aligned influences, p^l on them, and Δp, as lod::geomorph makes them.

TEST_F(LodServiceTest, GeomorphSendsTheAlignedInfluencesAndDelta) {
  // A level whose aligned set is larger than its own (some vertex collapses into one with a bone
  // it lacks), so that sending the level's own influences would be caught.
  int l = -1;
  for (int k = 0; k + 1 < levels_->count() && l < 0; ++k) {
    if (lod::geomorph(*levels_, k).aligned.influence_count() > level(k).model.influences.influence_count()) l = k;
  }
  ASSERT_GE(l, 0) << "no level of the demo arm gains influences when aligned";
  v1::GetLodRequest request = level_request(static_cast<uint32_t>(l), v1::GetLodRequest::FORM_ANIMATION_SPACE);
  request.set_include_geomorph(true);
  const LodMesh mesh = client_->get_lod(request);
  const lod::Geomorph morph = lod::geomorph(*levels_, l);
  EXPECT_EQ(mesh.header.influence_count(), static_cast<uint32_t>(morph.aligned.influence_count()));
  EXPECT_TRUE(same_bytes(mesh.influence_offsets, as_u32(morph.aligned.offsets)));
  EXPECT_TRUE(same_bytes(mesh.bone_indices, as_u32(morph.aligned.bones)));
  EXPECT_TRUE(same_bytes(mesh.animation_positions, as_f32(morph.position)));
  EXPECT_TRUE(same_bytes(mesh.geomorph_delta, as_f32(morph.delta)));
  EXPECT_TRUE(same_bytes(mesh.indices, faces_u32(level(l).model.faces)));

  // The coarsest level morphs to nothing: its own influences, Δp = 0.
  const int last = levels_->count() - 1;
  request.set_level(static_cast<uint32_t>(last));
  const LodMesh coarsest = client_->get_lod(request);
  const ExpectedLevel want = expected(last);
  EXPECT_TRUE(same_bytes(coarsest.influence_offsets, want.offsets));
  EXPECT_TRUE(same_bytes(coarsest.animation_positions, want.positions));
  EXPECT_TRUE(same_bytes(coarsest.geomorph_delta, std::vector<float>(want.positions.size(), 0.0f)));
}

// ---------------------------------------------------------------------------------------------
// Choosing the level: by pixel tolerance (eq. 7.2) and by budget.

TEST_F(LodServiceTest, PixelToleranceChoosesTheLevelEq72Chooses) {
  std::set<uint32_t> seen;
  const float tolerance = 1.5f;
  const float fov = 0.8f;
  for (double factor : {0.5, 1.5, 4.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 1e4}) {
    const auto distance = static_cast<float>(factor * radius_);
    SCOPED_TRACE("distance " + std::to_string(distance));
    lod::PixelTolerance view;
    view.tolerance_px = tolerance;
    view.viewport_width_px = 1920;
    view.horizontal_fov_rad = fov;
    view.distance = distance;
    auto choice = lod::level_for_view(*levels_, view, radius_);
    ASSERT_TRUE(choice.ok());
    const LodMesh mesh = client_->get_lod(view_request(tolerance, distance, fov));
    EXPECT_EQ(mesh.header.level(), static_cast<uint32_t>(choice->level));
    EXPECT_EQ(mesh.header.epsilon(), static_cast<float>(level(choice->level).epsilon));
    EXPECT_EQ(mesh.header.tolerated_error(), static_cast<float>(choice->tolerated_error));
    EXPECT_LE(mesh.header.epsilon(), mesh.header.tolerated_error());
    EXPECT_EQ(mesh.header.vertex_count(), static_cast<uint32_t>(level(choice->level).model.vertex_count()));
    seen.insert(mesh.header.level());
  }
  EXPECT_GE(seen.size(), 3u) << "the distances should span several levels";
  EXPECT_TRUE(seen.count(0));
}

TEST_F(LodServiceTest, BudgetPicksTheFinestLevelWithinIt) {
  auto finest_within = [](int64_t budget) {
    for (int l = 0; l < levels_->count(); ++l) {
      if (level(l).model.vertex_count() <= budget) return l;
    }
    return -1;
  };
  std::vector<int64_t> budgets = {std::numeric_limits<uint32_t>::max()};
  for (int l = 0; l < levels_->count(); ++l) {
    budgets.push_back(level(l).model.vertex_count());
    budgets.push_back(level(l).model.vertex_count() + 1);
    if (l + 1 < levels_->count()) budgets.push_back(level(l).model.vertex_count() - 1);
  }
  for (int64_t budget : budgets) {
    SCOPED_TRACE("budget " + std::to_string(budget));
    v1::GetLodRequest request;
    request.mutable_model()->set_name(kModel);
    request.set_form(v1::GetLodRequest::FORM_ANIMATION_SPACE);
    request.mutable_budget()->set_max_vertices(static_cast<uint32_t>(budget));
    const LodMesh mesh = client_->get_lod(request);
    const int want = finest_within(budget);
    ASSERT_GE(want, 0);
    EXPECT_EQ(mesh.header.level(), static_cast<uint32_t>(want));
    EXPECT_LE(mesh.header.vertex_count(), budget);
    EXPECT_TRUE(same_bytes(mesh.influence_offsets, expected(want).offsets));
  }
}

// A PMSC model that carries an animation-space posing engine serves the engine's levels.
TEST_F(LodServiceTest, PmscModelWithAnEngineServesTheEnginesLevels) {
  const LodMesh mesh = client_->get_lod(level_request(0, v1::GetLodRequest::FORM_POSED, "arm-pmsc-engine"));
  EXPECT_GE(mesh.header.level_count(), 1u);
  EXPECT_GT(mesh.header.vertex_count(), 0u);
  EXPECT_EQ(mesh.positions.size(), size_t{mesh.header.vertex_count()} * 3);
}

// ---------------------------------------------------------------------------------------------
// Bad requests: the exact status, a message naming the field, and nothing streamed.

struct BadCase {
  const char* name;
  grpc::StatusCode code;
  std::string message_part;
  std::function<void(v1::GetLodRequest&)> edit;
};

TEST_F(LodServiceTest, BadRequestsGetTheExactStatusAndNameTheField) {
  const int last = levels_->count() - 1;
  const std::string coarsest = std::to_string(level(last).model.vertex_count());
  const std::string bones = std::to_string(model_->bone_count());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  auto view = [](v1::GetLodRequest& r) -> v1::PixelTolerance& {
    auto* v = r.mutable_pixel_tolerance();
    v->set_tolerance_px(1.5f);
    v->set_viewport_width_px(1920);
    v->set_horizontal_fov_rad(0.8f);
    v->set_distance(10);
    return *v;
  };
  const std::vector<BadCase> cases = {
      {"no selection", grpc::StatusCode::INVALID_ARGUMENT,
       "selection: expected one of pixel_tolerance, budget or level, got none", [](auto& r) { r.clear_level(); }},
      {"negative tolerance", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.tolerance_px: expected a finite value > 0, got -1",
       [&](auto& r) { view(r).set_tolerance_px(-1); }},
      {"NaN tolerance", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.tolerance_px: expected a finite value > 0, got nan",
       [&](auto& r) { view(r).set_tolerance_px(nan); }},
      {"zero viewport", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.viewport_width_px: expected a finite value > 0, got 0",
       [&](auto& r) { view(r).set_viewport_width_px(0); }},
      {"zero field of view", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.horizontal_fov_rad: expected a value in (0, π), got 0",
       [&](auto& r) { view(r).set_horizontal_fov_rad(0); }},
      {"field of view past π", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.horizontal_fov_rad: expected a value in (0, π), got 4",
       [&](auto& r) { view(r).set_horizontal_fov_rad(4); }},
      {"negative distance", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.distance: expected a finite value > 0, got -1", [&](auto& r) { view(r).set_distance(-1); }},
      {"infinite distance", grpc::StatusCode::INVALID_ARGUMENT,
       "pixel_tolerance.distance: expected a finite value > 0, got inf", [&](auto& r) { view(r).set_distance(inf); }},
      {"level out of range", grpc::StatusCode::INVALID_ARGUMENT,
       "level: expected 0.." + std::to_string(last) + " (model 'arm-animspace' has " +
           std::to_string(levels_->count()) + " levels), got 99",
       [](auto& r) { r.set_level(99); }},
      {"budget below the coarsest level", grpc::StatusCode::OUT_OF_RANGE,
       "budget.max_vertices: expected at least " + coarsest + " (the coarsest level's vertex count), got 3",
       [](auto& r) { r.mutable_budget()->set_max_vertices(3); }},
      {"zero budget", grpc::StatusCode::OUT_OF_RANGE, "budget.max_vertices: expected at least " + coarsest,
       [](auto& r) { r.mutable_budget()->set_max_vertices(0); }},
      {"form unspecified", grpc::StatusCode::INVALID_ARGUMENT,
       "form: expected FORM_ANIMATION_SPACE or FORM_POSED, got FORM_UNSPECIFIED",
       [](auto& r) { r.set_form(v1::GetLodRequest::FORM_UNSPECIFIED); }},
      {"form unknown", grpc::StatusCode::INVALID_ARGUMENT, "form: expected FORM_ANIMATION_SPACE or FORM_POSED, got 7",
       [](auto& r) { r.set_form(static_cast<Form>(7)); }},
      {"pose with the animation-space form", grpc::StatusCode::INVALID_ARGUMENT,
       "pose: expected no pose with FORM_ANIMATION_SPACE",
       [&](auto& r) {
         r.set_form(v1::GetLodRequest::FORM_ANIMATION_SPACE);
         *r.mutable_pose() = testing::global_skeleton_pose(model_->skeleton.rest);
       }},
      {"geomorph with the posed form", grpc::StatusCode::INVALID_ARGUMENT,
       "include_geomorph: expected FORM_ANIMATION_SPACE (Δp is per influence, §7.3), got FORM_POSED",
       [](auto& r) { r.set_include_geomorph(true); }},
      {"pose bone count", grpc::StatusCode::INVALID_ARGUMENT, "pose.bone_count: expected " + bones + ", got 2",
       [&](auto& r) {
         as::TransformList two(model_->skeleton.rest.begin(), model_->skeleton.rest.begin() + 2);
         *r.mutable_pose() = testing::global_skeleton_pose(two);
       }},
      {"pose space", grpc::StatusCode::INVALID_ARGUMENT, "pose.space: expected SPACE_LOCAL or SPACE_GLOBAL, got 0",
       [&](auto& r) {
         *r.mutable_pose() = testing::global_skeleton_pose(model_->skeleton.rest);
         r.mutable_pose()->set_space(v1::SkeletonPose::SPACE_UNSPECIFIED);
       }},
      {"pose NaN", grpc::StatusCode::INVALID_ARGUMENT, "pose.transforms: bone 1, entry (0,3) is NaN",
       [&](auto& r) {
         as::TransformList pose = model_->skeleton.rest;
         pose[1](0, 3) = std::numeric_limits<double>::quiet_NaN();
         *r.mutable_pose() = testing::global_skeleton_pose(pose);
       }},
      {"oversize chunks", grpc::StatusCode::INVALID_ARGUMENT,
       "vertices_per_chunk: expected 0 (the default, 65536) or 1..1048576, got 2000000",
       [](auto& r) { r.set_vertices_per_chunk(2000000); }},
      {"empty model name", grpc::StatusCode::INVALID_ARGUMENT, "model.name is empty",
       [](auto& r) { r.mutable_model()->set_name(""); }},
      {"unknown model", grpc::StatusCode::NOT_FOUND, "model 'nosuch' is not loaded",
       [](auto& r) { r.mutable_model()->set_name("nosuch"); }},
      {"unknown version", grpc::StatusCode::NOT_FOUND, "model 'arm-animspace' has no servable version 99",
       [](auto& r) { r.mutable_model()->set_version(99); }},
      {"PMSC model without an engine", grpc::StatusCode::FAILED_PRECONDITION,
       "model 'arm-pmsc' version 1 is of kind pmsc and has no skeleton",
       [](auto& r) { r.mutable_model()->set_name("arm-pmsc"); }},
      {"mesh sequence", grpc::StatusCode::FAILED_PRECONDITION, "model 'arm' version 1 is of kind mesh_sequence",
       [](auto& r) { r.mutable_model()->set_name("arm"); }},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.name);
    v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_POSED);
    c.edit(request);
    const RawStream raw = raw_stream(channel(), request);
    EXPECT_EQ(raw.status.error_code(), c.code) << raw.status.error_message();
    EXPECT_NE(raw.status.error_message().find(c.message_part), std::string::npos)
        << "message: " << raw.status.error_message() << "\nexpected to contain: " << c.message_part;
    EXPECT_TRUE(raw.chunks.empty()) << "a refused call streams nothing";
  }
  // The client library reports the same as an RpcError.
  try {
    client_->get_lod(level_request(99, v1::GetLodRequest::FORM_POSED));
    ADD_FAILURE() << "expected an RpcError";
  } catch (const RpcError& error) {
    EXPECT_EQ(error.code(), grpc::StatusCode::INVALID_ARGUMENT);
  }
  // The daemon is still serving.
  EXPECT_EQ(client_->get_lod(level_request(0, v1::GetLodRequest::FORM_POSED)).header.level(), 0u);
}

// A large mesh travels in blocks of at most 65536 vertices or faces by default, none of them a
// giant message, and reassembles to the core's evaluation.
TEST_F(LodServiceTest, LargeMeshStreamsInDefaultBlocks) {
  const auto V = static_cast<uint64_t>(sheet_->vertex_count());
  const auto F = static_cast<uint64_t>(sheet_->faces.rows());
  const LodMesh mesh = client_->get_lod(level_request(0, v1::GetLodRequest::FORM_POSED, "sheet"));
  EXPECT_EQ(mesh.header.vertex_count(), V);
  EXPECT_EQ(mesh.chunk_count, 1 + (V + 65535) / 65536 + (F + 65535) / 65536);
  PointMatrix want;
  as::evaluate(*sheet_, sheet_->skeleton.rest, want);
  EXPECT_TRUE(same_bytes(mesh.positions, points_f32(want)));
  EXPECT_TRUE(same_bytes(mesh.indices, faces_u32(sheet_->faces)));
  EXPECT_LT(mesh.bytes_received / mesh.chunk_count, uint64_t{1} << 20);

  const RawStream raw = raw_stream(channel(), level_request(0, v1::GetLodRequest::FORM_ANIMATION_SPACE, "sheet"));
  ASSERT_TRUE(raw.status.ok()) << raw.status.error_message();
  for (const auto& chunk : raw.chunks) EXPECT_LE(chunk.ByteSizeLong(), size_t{4} << 20);
}

// A cancelled stream stops — one of several hundred thousand one-vertex blocks in, far more than
// flow control lets the server run ahead — and the daemon serves the next call.
TEST_F(LodServiceTest, CancelledStreamStops) {
  auto stub = v1::LodService::NewStub(channel());
  v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_ANIMATION_SPACE, "sheet");
  request.set_vertices_per_chunk(1);
  grpc::ClientContext context;
  auto reader = stub->GetLod(&context, request);
  v1::LodChunk chunk;
  ASSERT_TRUE(reader->Read(&chunk));
  ASSERT_TRUE(chunk.has_header());
  ASSERT_TRUE(reader->Read(&chunk));
  context.TryCancel();
  size_t after = 0;
  while (reader->Read(&chunk)) ++after;
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  // The whole stream is 1 + V + F chunks (one-vertex blocks, one-face blocks at this setting).
  EXPECT_LT(after, static_cast<size_t>(sheet_->vertex_count() + sheet_->faces.rows()));
  EXPECT_EQ(client_->get_lod(level_request(1, v1::GetLodRequest::FORM_POSED)).header.level(), 1u);
}

// ---------------------------------------------------------------------------------------------
// `animspace lod`: the file a DCC tool opens.

TEST_F(LodServiceTest, CliWritesAGlbThatTinygltfLoads) {
  TempDir out;
  // A distance that makes eq. 7.2 choose a coarse level, computed here.
  lod::PixelTolerance view;
  view.tolerance_px = 1.5f;
  view.viewport_width_px = 1920;
  view.horizontal_fov_rad = static_cast<float>(45 * 3.14159265358979323846 / 180);
  int chosen = 0;
  double distance = 0;
  for (double factor : {10.0, 30.0, 100.0, 300.0, 1000.0}) {
    view.distance = static_cast<float>(factor * radius_);
    auto choice = lod::level_for_view(*levels_, view, radius_);
    ASSERT_TRUE(choice.ok());
    chosen = choice->level;
    distance = factor * radius_;
    if (chosen >= 2) break;
  }
  ASSERT_GE(chosen, 2);
  const auto glb = out / "arm.glb";
  char distance_text[32];
  std::snprintf(distance_text, sizeof(distance_text), "%.9g", static_cast<double>(static_cast<float>(distance)));
  int code = 0;
  std::string errors;
  const std::string printed = run_cli("--server " + daemon_->address() + " --json lod arm-animspace --tolerance-px 1.5 "
                                      "--distance " + distance_text + " -o " + glb.string(),
                                      &code, &errors);
  ASSERT_EQ(code, 0) << printed << errors;
  const auto summary = nlohmann::json::parse(printed);
  const lod::LodLevel& core = level(chosen);
  EXPECT_EQ(summary["level"].get<int>(), chosen);
  EXPECT_EQ(summary["vertices"].get<int>(), core.model.vertex_count());
  EXPECT_EQ(summary["faces"].get<int64_t>(), core.model.faces.rows());
  EXPECT_FLOAT_EQ(summary["epsilon"].get<float>(), static_cast<float>(core.epsilon));
  EXPECT_GT(summary["tolerated_error"].get<double>(), 0);
  EXPECT_GE(summary["chunks"].get<int>(), 3);
  EXPECT_GT(summary["bytes_received"].get<int64_t>(), 12 * core.model.vertex_count());

  tinygltf::TinyGLTF loader;
  tinygltf::Model gltf;
  std::string error, warning;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&gltf, &error, &warning, glb.string())) << error;
  ASSERT_EQ(gltf.meshes.size(), 1u);
  ASSERT_EQ(gltf.meshes[0].primitives.size(), 1u);
  const tinygltf::Primitive& primitive = gltf.meshes[0].primitives[0];
  const tinygltf::Accessor& positions = gltf.accessors[static_cast<size_t>(primitive.attributes.at("POSITION"))];
  const tinygltf::Accessor& indices = gltf.accessors[static_cast<size_t>(primitive.indices)];
  EXPECT_EQ(positions.count, static_cast<size_t>(core.model.vertex_count()));
  EXPECT_EQ(indices.count, static_cast<size_t>(3 * core.model.faces.rows()));
  // The bounds are the posed level's (rest pose), which the writer reorders but does not move.
  PointMatrix rest;
  as::evaluate(core.model, core.model.skeleton.rest, rest);
  ASSERT_EQ(positions.minValues.size(), 3u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_FLOAT_EQ(static_cast<float>(positions.minValues[static_cast<size_t>(c)]), rest.col(c).minCoeff());
    EXPECT_FLOAT_EQ(static_cast<float>(positions.maxValues[static_cast<size_t>(c)]), rest.col(c).maxCoeff());
  }
}

// `animspace lod --pose-file`: the mesh at a pose, point for point; refusals exit non-zero.
TEST_F(LodServiceTest, CliPosesTheLevelAndReportsRefusals) {
  TempDir out;
  const as::TransformList pose = stored_pose(11);
  const auto pose_file = out / "pose.txt";
  {
    std::ofstream file(pose_file);
    file << "# G_j, top three rows, row-major\n";
    char number[32];
    for (const auto& G : pose) {
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) {
          std::snprintf(number, sizeof(number), "%.9g ", static_cast<double>(static_cast<float>(G(r, c))));
          file << number;
        }
      }
      file << "\n";
    }
  }
  const auto obj = out / "posed.obj";
  int code = 0;
  std::string errors;
  std::string printed = run_cli("--server " + daemon_->address() + " lod arm-animspace --level 2 --pose-file " +
                                    pose_file.string() + " --vertices-per-chunk 100 -o " + obj.string(),
                                &code, &errors);
  ASSERT_EQ(code, 0) << printed << errors;
  auto mesh = mesh_io::read_triangle_mesh(obj);
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  PointMatrix want;
  as::evaluate(level(2).model, pose, want);
  auto sorted = [](const PointMatrix& points) {
    std::vector<std::array<float, 3>> rows;
    for (Eigen::Index i = 0; i < points.rows(); ++i) rows.push_back({points(i, 0), points(i, 1), points(i, 2)});
    std::sort(rows.begin(), rows.end());
    return rows;
  };
  EXPECT_EQ(mesh->F.rows(), level(2).model.faces.rows());
  EXPECT_EQ(sorted(mesh->V), sorted(want));  // reordered for the vertex cache, the same points

  // A model without levels: the RPC's refusal, exit status 3, no file.
  const auto refused = out / "refused.obj";
  printed = run_cli("--server " + daemon_->address() + " lod arm-pmsc --level 0 -o " + refused.string(), &code,
                    &errors);
  EXPECT_EQ(code, 3) << errors;
  EXPECT_NE(errors.find("FAILED_PRECONDITION"), std::string::npos) << errors;
  EXPECT_FALSE(std::filesystem::exists(refused));
  // No selection, or a tolerance without a distance: refused by the command line itself.
  printed = run_cli("--server " + daemon_->address() + " lod arm-animspace -o " + refused.string(), &code);
  EXPECT_NE(code, 0) << printed;
  printed = run_cli("--server " + daemon_->address() + " lod arm-animspace --tolerance-px 1 -o " + refused.string(),
                    &code);
  EXPECT_NE(code, 0) << printed;
  EXPECT_FALSE(std::filesystem::exists(refused));
}

// ---------------------------------------------------------------------------------------------
// The texture atlas (issue #37): per-corner UVs of level 0, the stored float64 rounded to float32.

TEST_F(LodServiceTest, TextureCoordinatesAreTheStoredAtlasPerCorner) {
  std::vector<float> want(static_cast<size_t>(atlas_->uvs.size()));
  for (size_t i = 0; i < want.size(); ++i) want[i] = static_cast<float>(atlas_->uvs.data()[i]);  // row-major: u, v
  v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_POSED, kAtlasModel);
  const LodMesh plain = client_->get_lod(request);
  EXPECT_FALSE(plain.header.texture_coordinates());
  EXPECT_TRUE(plain.corner_uvs.empty()) << "UVs only when asked for";

  request.set_include_texture_coordinates(true);
  const LodMesh with = client_->get_lod(request);
  EXPECT_TRUE(with.header.texture_coordinates());
  EXPECT_TRUE(same_bytes(with.corner_uvs, want));
  // The mesh itself is unchanged: same vertices, same faces (UVs are per corner, not per vertex).
  EXPECT_TRUE(same_bytes(with.positions, plain.positions));
  EXPECT_TRUE(same_bytes(with.indices, plain.indices));
  EXPECT_TRUE(same_bytes(with.indices, faces_u32(model_->faces)));

  // Small blocks: each face block carries its faces' UVs, reassembled to the same.
  request.set_vertices_per_chunk(7);
  const RawStream raw = raw_stream(channel(), request);
  ASSERT_TRUE(raw.status.ok()) << raw.status.error_message();
  int face_blocks = 0;
  for (const v1::LodChunk& chunk : raw.chunks) {
    if (chunk.payload_case() != v1::LodChunk::kFaces) continue;
    ++face_blocks;
    EXPECT_LE(chunk.faces().face_count(), 7u);
    EXPECT_EQ(chunk.faces().texture_coordinates().size(), size_t{chunk.faces().face_count()} * 24);
  }
  EXPECT_EQ(face_blocks, static_cast<int>((model_->faces.rows() + 6) / 7));
  const LodMesh small = client_->get_lod(request);
  EXPECT_TRUE(same_bytes(small.corner_uvs, want));
}

// With UVs a face costs 36 bytes: blocks under a small --max-message-bytes hold fewer faces.
TEST_F(LodServiceTest, TextureCoordinatesKeepFaceBlocksInTheByteBudget) {
  TempDir work;
  const auto repo = work.path() / "repo";
  std::filesystem::create_directories(repo);
  std::filesystem::copy(repo_ / kAtlasModel, repo / kAtlasModel, std::filesystem::copy_options::recursive);
  const int64_t limit = 4096;  // blocks get a quarter: 1024 bytes, 28 faces with UVs (85 without)
  DaemonProcess daemon({"--model-repository", repo.string(), "--max-message-bytes", std::to_string(limit)},
                       work.path());
  Client client(daemon.address());
  ASSERT_TRUE(testing::wait_until_serving(client));
  v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_POSED, kAtlasModel);
  request.set_include_texture_coordinates(true);
  const RawStream raw = raw_stream(client.channel(), request);
  ASSERT_TRUE(raw.status.ok()) << raw.status.error_message();
  uint32_t most = 0;
  for (const v1::LodChunk& chunk : raw.chunks) {
    EXPECT_LE(chunk.ByteSizeLong(), static_cast<size_t>(limit));
    if (chunk.payload_case() == v1::LodChunk::kFaces) most = std::max(most, chunk.faces().face_count());
  }
  EXPECT_EQ(most, static_cast<uint32_t>(std::min<int64_t>(limit / 4 / 36, model_->faces.rows())));
}

TEST_F(LodServiceTest, TextureCoordinatesRefusalsNameTheField) {
  // arm-atlas's levels are arm-animspace's, built before its atlas: they have no UVs.
  const std::vector<BadCase> cases = {
      {"a coarser level built without the atlas", grpc::StatusCode::FAILED_PRECONDITION,
       "include_texture_coordinates: level 1 of model 'arm-atlas' version 1 stores no texture coordinates (its "
       "levels were built without the atlas",
       [](auto& r) { r.set_level(1); }},
      {"a budget that picks such a level", grpc::StatusCode::FAILED_PRECONDITION,
       "include_texture_coordinates: level " + std::to_string(levels_->count() - 1) +
           " of model 'arm-atlas' version 1 stores no texture coordinates",
       [&](auto& r) {
         r.mutable_budget()->set_max_vertices(static_cast<uint32_t>(level(levels_->count() - 1).model.vertex_count()));
       }},
      {"the animation-space form", grpc::StatusCode::INVALID_ARGUMENT,
       "include_texture_coordinates: expected FORM_POSED (UVs go with the drawn mesh), got FORM_ANIMATION_SPACE",
       [](auto& r) { r.set_form(v1::GetLodRequest::FORM_ANIMATION_SPACE); }},
      {"a model without an atlas", grpc::StatusCode::FAILED_PRECONDITION,
       "include_texture_coordinates: model 'arm-animspace' version 1 stores no texture atlas",
       [](auto& r) { r.mutable_model()->set_name(kModel); }},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.name);
    v1::GetLodRequest request = level_request(0, v1::GetLodRequest::FORM_POSED, kAtlasModel);
    request.set_include_texture_coordinates(true);
    c.edit(request);
    const RawStream raw = raw_stream(channel(), request);
    EXPECT_EQ(raw.status.error_code(), c.code) << raw.status.error_message();
    EXPECT_NE(raw.status.error_message().find(c.message_part), std::string::npos)
        << "message: " << raw.status.error_message() << "\nexpected to contain: " << c.message_part;
    EXPECT_TRUE(raw.chunks.empty()) << "a refused call streams nothing";
  }
}

// Every level of a model whose levels were built under its atlas (the demo's arm-smooth) serves
// its UVs: the stored level's, and each corner the atlas's UV of its vertex in its face's chart.
TEST_F(LodServiceTest, TextureCoordinatesAtEveryLevelOfAModelBuiltWithItsAtlas) {
  // The demo's subdivided arm: an atlas made by `animspace atlas`'s code and levels that keep it.
  // Added and loaded here alone: the suite's other tests do not use it.
  const std::string name(demo::kDemoSmoothModelName);
  ASSERT_TRUE(testing::write_demo_smooth(repo_).ok());
  client_->load_model(name, 1);
  auto in = container::read_file(repo_ / name / "1" / "model.anim");
  ASSERT_TRUE(in.ok()) << in.error().message;
  auto smooth = as::load(*in, name);
  ASSERT_TRUE(smooth.ok()) << smooth.error().message;
  auto levels = lod::load_levels(*in, *smooth, name);
  ASSERT_TRUE(levels.ok()) << levels.error().message;
  auto stored = atlas::load_atlas(*in, smooth->faces.rows(), name);
  ASSERT_TRUE(stored.ok() && stored->has_value());
  const atlas::Atlas& a = **stored;
  std::map<std::pair<int32_t, int32_t>, std::array<float, 2>> uv;  // (vertex, chart), as float32
  for (Eigen::Index f = 0; f < smooth->faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      uv[{smooth->faces(f, k), a.chart_of_face[static_cast<size_t>(f)]}] = {static_cast<float>(a.uvs(3 * f + k, 0)),
                                                                            static_cast<float>(a.uvs(3 * f + k, 1))};
    }
  }
  ASSERT_GE(levels->count(), 3);
  for (int l = 1; l < levels->count(); ++l) {
    SCOPED_TRACE("level " + std::to_string(l));
    const lod::LodLevel& level = levels->levels[static_cast<size_t>(l)];
    v1::GetLodRequest request = level_request(static_cast<uint32_t>(l), v1::GetLodRequest::FORM_POSED, name);
    request.set_include_texture_coordinates(true);
    request.set_vertices_per_chunk(50);
    const LodMesh mesh = client_->get_lod(request);
    ASSERT_TRUE(mesh.header.texture_coordinates());
    ASSERT_EQ(mesh.header.level(), static_cast<uint32_t>(l));
    EXPECT_TRUE(same_bytes(mesh.indices, faces_u32(level.model.faces)));
    ASSERT_EQ(mesh.corner_uvs.size(), static_cast<size_t>(6 * level.model.faces.rows()));
    for (Eigen::Index f = 0; f < level.model.faces.rows(); ++f) {
      const int32_t chart = a.chart_of_face[static_cast<size_t>(level.face_ids[static_cast<size_t>(f)])];
      for (int k = 0; k < 3; ++k) {
        const auto at = uv.find({level.vertex_ids[static_cast<size_t>(level.model.faces(f, k))], chart});
        ASSERT_NE(at, uv.end()) << "face " << f << " corner " << k << " is no vertex of its chart";
        EXPECT_EQ(mesh.corner_uvs[static_cast<size_t>(6 * f + 2 * k)], at->second[0]) << "face " << f;
        EXPECT_EQ(mesh.corner_uvs[static_cast<size_t>(6 * f + 2 * k + 1)], at->second[1]) << "face " << f;
      }
    }
  }
}

// `animspace lod --texture-coordinates`: a glTF whose every corner has its position and the
// atlas's UV for that corner (seams split: one vertex per distinct UV).
TEST_F(LodServiceTest, CliWritesTheAtlasAsTexcoord0) {
  TempDir out;
  const auto glb = out / "arm.glb";
  int code = 0;
  std::string errors;
  const std::string printed = run_cli("--server " + daemon_->address() + " --json lod " + kAtlasModel +
                                          " --level 0 --texture-coordinates -o " + glb.string(),
                                      &code, &errors);
  ASSERT_EQ(code, 0) << printed << errors;
  EXPECT_TRUE(nlohmann::json::parse(printed)["texture_coordinates"].get<bool>());

  // Every corner of the model, at the rest pose: (float position, UV).
  PointMatrix rest;
  as::evaluate(*model_, model_->skeleton.rest, rest);
  std::vector<std::array<float, 5>> corners;
  for (Eigen::Index f = 0; f < model_->faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const auto v = model_->faces(f, k);
      corners.push_back({static_cast<float>(rest(v, 0)), static_cast<float>(rest(v, 1)),
                         static_cast<float>(rest(v, 2)), static_cast<float>(atlas_->uvs(3 * f + k, 0)),
                         static_cast<float>(atlas_->uvs(3 * f + k, 1))});
    }
  }
  std::sort(corners.begin(), corners.end());

  tinygltf::TinyGLTF loader;
  tinygltf::Model gltf;
  std::string error, warning;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&gltf, &error, &warning, glb.string())) << error;
  const tinygltf::Primitive& primitive = gltf.meshes.at(0).primitives.at(0);
  ASSERT_TRUE(primitive.attributes.count("TEXCOORD_0"));
  auto floats = [&](int index, int width) {
    const tinygltf::Accessor& a = gltf.accessors[static_cast<size_t>(index)];
    const tinygltf::BufferView& view = gltf.bufferViews[static_cast<size_t>(a.bufferView)];
    const size_t stride = view.byteStride != 0 ? view.byteStride : sizeof(float) * static_cast<size_t>(width);
    std::vector<float> values;
    for (size_t i = 0; i < a.count; ++i) {
      for (int c = 0; c < width; ++c) {
        float x;
        std::memcpy(&x, gltf.buffers[static_cast<size_t>(view.buffer)].data.data() + view.byteOffset + a.byteOffset +
                            i * stride + sizeof(float) * static_cast<size_t>(c),
                    sizeof x);
        values.push_back(x);
      }
    }
    return values;
  };
  const std::vector<float> positions = floats(primitive.attributes.at("POSITION"), 3);
  const std::vector<float> uvs = floats(primitive.attributes.at("TEXCOORD_0"), 2);
  ASSERT_EQ(uvs.size() / 2, positions.size() / 3);
  // Every corner has its own UV here, so every corner is its own vertex.
  EXPECT_EQ(positions.size() / 3, corners.size());
  const tinygltf::Accessor& indices = gltf.accessors[static_cast<size_t>(primitive.indices)];
  const tinygltf::BufferView& view = gltf.bufferViews[static_cast<size_t>(indices.bufferView)];
  ASSERT_EQ(indices.count, corners.size());
  size_t matched = 0;
  for (size_t i = 0; i < indices.count; ++i) {
    const unsigned char* at =
        gltf.buffers[static_cast<size_t>(view.buffer)].data.data() + view.byteOffset + indices.byteOffset;
    size_t v = 0;
    if (indices.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) {
      uint32_t x;
      std::memcpy(&x, at + 4 * i, 4);
      v = x;
    } else {
      ASSERT_EQ(indices.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
      uint16_t x;
      std::memcpy(&x, at + 2 * i, 2);
      v = x;
    }
    // glTF's v runs down: the file holds 1 − v.
    const std::array<float, 3> p = {positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]};
    const float u = uvs[2 * v], w = 1.0f - uvs[2 * v + 1];
    auto first = std::lower_bound(corners.begin(), corners.end(), std::array<float, 5>{p[0], p[1], p[2], -1.f, -1.f});
    bool found = false;
    for (auto it = first; it != corners.end() && (*it)[0] == p[0] && (*it)[1] == p[1] && (*it)[2] == p[2]; ++it) {
      if (std::abs((*it)[3] - u) <= 1e-6f && std::abs((*it)[4] - w) <= 1e-6f) found = true;
    }
    if (found) ++matched;
  }
  EXPECT_EQ(matched, corners.size()) << "every corner of the file is a corner of the model with its atlas UV";
}

}  // namespace
}  // namespace animspace
