#include "core/mesh_io/posed_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include "tests/support/tiny_gltf.h"

#include "core/common/atomic_file.h"
#include "core/mesh_io/triangle_mesh_io.h"
#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::TempDir;

// An n × n grid of vertices on a wavy sheet with 2 (n − 1)² triangles, with per-vertex unit
// normals; faces and vertices are shuffled (a cache-hostile order) and `unused` vertices that no
// face uses are mixed in.
PosedMesh shuffled_grid(int n, int unused, uint64_t seed) {
  std::mt19937_64 engine(seed);
  const int used = n * n;
  const int total = used + unused;
  std::vector<int> slot(static_cast<size_t>(total));
  std::iota(slot.begin(), slot.end(), 0);
  std::shuffle(slot.begin(), slot.end(), engine);  // grid vertex v lives at row slot[v]

  PosedMesh mesh;
  mesh.points.resize(total, 3);
  mesh.normals.resize(total, 3);
  for (int v = 0; v < total; ++v) {
    const float x = static_cast<float>(v % n) / static_cast<float>(n);
    const float y = static_cast<float>(v / n) / static_cast<float>(n);
    const float z = 0.1f * std::sin(7 * x) * std::cos(5 * y) + (v >= used ? 10.0f : 0.0f);
    mesh.points.row(slot[static_cast<size_t>(v)]) << x, y, z;
    Eigen::RowVector3f normal(-0.7f * std::cos(7 * x) * std::cos(5 * y), 0.5f * std::sin(7 * x) * std::sin(5 * y),
                              1.0f);
    mesh.normals.row(slot[static_cast<size_t>(v)]) = normal.normalized();
  }
  std::vector<std::array<int32_t, 3>> faces;
  for (int i = 0; i + 1 < n; ++i) {
    for (int j = 0; j + 1 < n; ++j) {
      const int a = slot[static_cast<size_t>(i * n + j)], b = slot[static_cast<size_t>(i * n + j + 1)];
      const int c = slot[static_cast<size_t>((i + 1) * n + j)], d = slot[static_cast<size_t>((i + 1) * n + j + 1)];
      faces.push_back({a, b, d});
      faces.push_back({a, d, c});
    }
  }
  std::shuffle(faces.begin(), faces.end(), engine);
  mesh.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) {
    mesh.faces.row(static_cast<Eigen::Index>(f)) << faces[f][0], faces[f][1], faces[f][2];
  }
  return mesh;
}

// The triangles as sorted point triples, each rotated so that its smallest corner comes first
// (rotation keeps the orientation).
using Corner = std::array<float, 3>;
using TriangleKey = std::array<Corner, 3>;
std::vector<TriangleKey> triangle_multiset(const PointMatrix& points, const FaceMatrix& faces) {
  std::vector<TriangleKey> out;
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    TriangleKey key;
    for (int c = 0; c < 3; ++c) {
      const auto row = points.row(faces(f, c));
      key[static_cast<size_t>(c)] = {row(0), row(1), row(2)};
    }
    std::rotate(key.begin(), std::min_element(key.begin(), key.end()), key.end());
    out.push_back(key);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<unsigned int> index_list(const FaceMatrix& faces) {
  return std::vector<unsigned int>(faces.data(), faces.data() + faces.size());
}

float acmr(const PosedMesh& mesh) {
  const auto indices = index_list(mesh.faces);
  return meshopt_analyzeVertexCache(indices.data(), indices.size(), static_cast<size_t>(mesh.points.rows()), 16, 0, 0)
      .acmr;
}

// --- optimise_for_rendering ---

TEST(OptimiseForRenderingTest, KeepsTrianglesDropsUnusedVerticesNormalsFollow) {
  const PosedMesh mesh = shuffled_grid(30, 17, 1);
  const PosedMesh out = optimise_for_rendering(mesh);
  ASSERT_EQ(out.faces.rows(), mesh.faces.rows());
  ASSERT_EQ(out.points.rows(), 30 * 30);  // the 17 unused vertices are gone
  ASSERT_EQ(out.normals.rows(), out.points.rows());
  EXPECT_GE(out.faces.minCoeff(), 0);
  EXPECT_LT(out.faces.maxCoeff(), out.points.rows());
  EXPECT_EQ(triangle_multiset(out.points, out.faces), triangle_multiset(mesh.points, mesh.faces));

  // Every vertex is used, and fetched in order: the first uses of the vertices are 0, 1, 2, ….
  std::vector<char> seen(static_cast<size_t>(out.points.rows()), 0);
  int32_t next = 0;
  for (Eigen::Index i = 0; i < out.faces.size(); ++i) {
    const int32_t v = out.faces.data()[i];
    if (!seen[static_cast<size_t>(v)]) {
      EXPECT_EQ(v, next);
      seen[static_cast<size_t>(v)] = 1;
      ++next;
    }
  }
  EXPECT_EQ(next, out.points.rows());

  // Each output vertex carries the normal of the input vertex at the same (unique) position.
  std::map<Corner, Eigen::RowVector3f> normal_at;
  for (Eigen::Index v = 0; v < mesh.points.rows(); ++v) {
    normal_at[{mesh.points(v, 0), mesh.points(v, 1), mesh.points(v, 2)}] = mesh.normals.row(v);
  }
  ASSERT_EQ(normal_at.size(), static_cast<size_t>(mesh.points.rows()));
  for (Eigen::Index v = 0; v < out.points.rows(); ++v) {
    const auto found = normal_at.find({out.points(v, 0), out.points(v, 1), out.points(v, 2)});
    ASSERT_NE(found, normal_at.end());
    EXPECT_TRUE(out.normals.row(v) == found->second) << "vertex " << v;
  }
}

TEST(OptimiseForRenderingTest, ImprovesTheVertexCacheOfAShuffledGrid) {
  const PosedMesh mesh = shuffled_grid(60, 0, 2);
  const PosedMesh out = optimise_for_rendering(mesh);
  const float before = acmr(mesh);
  const float after = acmr(out);
  EXPECT_LE(after, before);
  EXPECT_LT(after, 0.9f * before) << "before " << before << ", after " << after;
  // Optimising an optimised mesh changes nothing of substance.
  EXPECT_LE(acmr(optimise_for_rendering(out)), after + 1e-6f);
}

TEST(OptimiseForRenderingTest, WithoutNormalsAndWithoutFaces) {
  PosedMesh mesh = shuffled_grid(8, 3, 3);
  mesh.normals.resize(0, 3);
  const PosedMesh out = optimise_for_rendering(mesh);
  EXPECT_EQ(out.normals.rows(), 0);
  EXPECT_EQ(out.points.rows(), 64);
  EXPECT_EQ(triangle_multiset(out.points, out.faces), triangle_multiset(mesh.points, mesh.faces));

  PosedMesh no_faces = shuffled_grid(4, 0, 4);
  no_faces.faces.resize(0, 3);
  const PosedMesh empty = optimise_for_rendering(no_faces);
  EXPECT_EQ(empty.points.rows(), 0);
  EXPECT_EQ(empty.faces.rows(), 0);
}

// --- glTF ---

bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
  return true;
}

struct LoadedGltf {
  tinygltf::Model model;
  bool ok = false;
  std::string error;
};

LoadedGltf load_glb(const std::string& bytes) {
  LoadedGltf loaded;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  std::string warning;
  loaded.ok = loader.LoadBinaryFromMemory(&loaded.model, &loaded.error, &warning,
                                          reinterpret_cast<const unsigned char*>(bytes.data()),
                                          static_cast<unsigned int>(bytes.size()), "");
  return loaded;
}

LoadedGltf load_gltf(const std::string& text) {
  LoadedGltf loaded;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  std::string warning;
  loaded.ok = loader.LoadASCIIFromString(&loaded.model, &loaded.error, &warning, text.data(),
                                         static_cast<unsigned int>(text.size()), "");
  return loaded;
}

// Copies an accessor's elements out (tightly packed views only, which is what we write).
template <typename T>
std::vector<T> accessor_values(const tinygltf::Model& model, int index, int components) {
  const tinygltf::Accessor& accessor = model.accessors.at(static_cast<size_t>(index));
  const tinygltf::BufferView& view = model.bufferViews.at(static_cast<size_t>(accessor.bufferView));
  const tinygltf::Buffer& buffer = model.buffers.at(static_cast<size_t>(view.buffer));
  const size_t count = accessor.count * static_cast<size_t>(components);
  EXPECT_EQ(view.byteLength, count * sizeof(T));
  std::vector<T> values(count);
  std::memcpy(values.data(), buffer.data.data() + view.byteOffset + accessor.byteOffset, count * sizeof(T));
  return values;
}

void expect_document_matches(const tinygltf::Model& model, const PosedMesh& mesh) {
  EXPECT_EQ(model.asset.version, "2.0");
  ASSERT_EQ(model.buffers.size(), 1u);
  ASSERT_EQ(model.scenes.size(), 1u);
  ASSERT_EQ(model.nodes.size(), 1u);
  EXPECT_EQ(model.nodes[0].mesh, 0);
  EXPECT_EQ(model.scenes[0].nodes, std::vector<int>{0});
  ASSERT_EQ(model.meshes.size(), 1u);
  ASSERT_EQ(model.meshes[0].primitives.size(), 1u);
  const tinygltf::Primitive& primitive = model.meshes[0].primitives[0];
  EXPECT_EQ(primitive.mode, TINYGLTF_MODE_TRIANGLES);

  const int position = primitive.attributes.at("POSITION");
  const tinygltf::Accessor& positions = model.accessors.at(static_cast<size_t>(position));
  EXPECT_EQ(positions.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
  EXPECT_EQ(positions.type, TINYGLTF_TYPE_VEC3);
  EXPECT_EQ(positions.count, static_cast<size_t>(mesh.points.rows()));
  EXPECT_EQ(model.bufferViews.at(static_cast<size_t>(positions.bufferView)).target, TINYGLTF_TARGET_ARRAY_BUFFER);
  const std::vector<float> xyz = accessor_values<float>(model, position, 3);
  EXPECT_TRUE(std::equal(xyz.begin(), xyz.end(), mesh.points.data()));
  ASSERT_EQ(positions.minValues.size(), 3u);
  ASSERT_EQ(positions.maxValues.size(), 3u);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_EQ(positions.minValues[static_cast<size_t>(axis)], mesh.points.col(axis).minCoeff());
    EXPECT_EQ(positions.maxValues[static_cast<size_t>(axis)], mesh.points.col(axis).maxCoeff());
  }

  if (mesh.normals.rows() != 0) {
    const int normal = primitive.attributes.at("NORMAL");
    const tinygltf::Accessor& normals = model.accessors.at(static_cast<size_t>(normal));
    EXPECT_EQ(normals.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
    EXPECT_EQ(normals.type, TINYGLTF_TYPE_VEC3);
    EXPECT_EQ(model.bufferViews.at(static_cast<size_t>(normals.bufferView)).target, TINYGLTF_TARGET_ARRAY_BUFFER);
    const std::vector<float> n = accessor_values<float>(model, normal, 3);
    EXPECT_TRUE(std::equal(n.begin(), n.end(), mesh.normals.data()));
  } else {
    EXPECT_EQ(primitive.attributes.count("NORMAL"), 0u);
  }

  const tinygltf::Accessor& indices = model.accessors.at(static_cast<size_t>(primitive.indices));
  EXPECT_EQ(indices.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
  EXPECT_EQ(indices.type, TINYGLTF_TYPE_SCALAR);
  EXPECT_EQ(model.bufferViews.at(static_cast<size_t>(indices.bufferView)).target,
            TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  const std::vector<uint32_t> read = accessor_values<uint32_t>(model, primitive.indices, 1);
  ASSERT_EQ(read.size(), static_cast<size_t>(mesh.faces.size()));
  for (size_t i = 0; i < read.size(); ++i) {
    ASSERT_EQ(read[i], static_cast<uint32_t>(mesh.faces.data()[i])) << "index " << i;
  }
}

TEST(GltfExportTest, GlbReadsBackAsWritten) {
  const PosedMesh mesh = optimise_for_rendering(shuffled_grid(20, 5, 5));
  const auto bytes = serialize_glb(mesh);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  ASSERT_GE(bytes->size(), 12u);
  EXPECT_EQ(bytes->substr(0, 4), "glTF");
  const LoadedGltf loaded = load_glb(*bytes);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  expect_document_matches(loaded.model, mesh);
}

TEST(GltfExportTest, GltfEmbedsItsBufferAndReadsBack) {
  const PosedMesh mesh = optimise_for_rendering(shuffled_grid(11, 0, 6));
  const auto text = serialize_gltf(mesh);
  ASSERT_TRUE(text.ok()) << text.error().message;
  EXPECT_NE(text->find("data:application/octet-stream;base64,"), std::string::npos);
  const LoadedGltf loaded = load_gltf(*text);
  ASSERT_TRUE(loaded.ok) << loaded.error;
  expect_document_matches(loaded.model, mesh);
}

TEST(GltfExportTest, WithoutNormalsAndUnoptimised) {
  // The serialisers write the mesh as given (no reordering), unused vertices included.
  PosedMesh mesh = shuffled_grid(6, 2, 7);
  mesh.normals.resize(0, 3);
  const auto bytes = serialize_glb(mesh);
  ASSERT_TRUE(bytes.ok()) << bytes.error().message;
  const LoadedGltf glb = load_glb(*bytes);
  ASSERT_TRUE(glb.ok) << glb.error;
  expect_document_matches(glb.model, mesh);
  const auto text = serialize_gltf(mesh);
  ASSERT_TRUE(text.ok()) << text.error().message;
  const LoadedGltf gltf = load_gltf(*text);
  ASSERT_TRUE(gltf.ok) << gltf.error;
  expect_document_matches(gltf.model, mesh);
}

TEST(GltfExportTest, RefusesBadMeshes) {
  const PosedMesh good = shuffled_grid(4, 0, 8);
  std::vector<std::pair<std::string, PosedMesh>> bad;
  {
    PosedMesh m;
    m.points.resize(0, 3);
    m.faces.resize(0, 3);
    bad.emplace_back("empty", m);
  }
  {
    PosedMesh m = good;
    m.faces.resize(0, 3);
    bad.emplace_back("no faces", m);
  }
  {
    PosedMesh m = good;
    m.points(3, 1) = std::numeric_limits<float>::quiet_NaN();
    bad.emplace_back("NaN point", m);
  }
  {
    PosedMesh m = good;
    m.points(0, 2) = std::numeric_limits<float>::infinity();
    bad.emplace_back("infinite point", m);
  }
  {
    PosedMesh m = good;
    m.faces(2, 1) = static_cast<int32_t>(m.points.rows());
    bad.emplace_back("index too large", m);
  }
  {
    PosedMesh m = good;
    m.faces(0, 0) = -1;
    bad.emplace_back("negative index", m);
  }
  {
    PosedMesh m = good;
    m.normals.conservativeResize(m.points.rows() - 1, 3);
    bad.emplace_back("normal count", m);
  }
  {
    PosedMesh m = good;
    m.normals(1, 0) = std::numeric_limits<float>::quiet_NaN();
    bad.emplace_back("NaN normal", m);
  }
  for (const auto& [what, mesh] : bad) {
    const auto glb = serialize_glb(mesh);
    ASSERT_FALSE(glb.ok()) << what;
    EXPECT_EQ(glb.error().code, ErrorCode::kInvalidArgument) << what;
    const auto gltf = serialize_gltf(mesh);
    ASSERT_FALSE(gltf.ok()) << what;
    EXPECT_EQ(gltf.error().code, ErrorCode::kInvalidArgument) << what;
    TempDir dir;
    const Status status = write_posed_mesh(dir / "bad.obj", mesh);
    ASSERT_FALSE(status.ok()) << what;
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument) << what;
    EXPECT_FALSE(std::filesystem::exists(dir / "bad.obj")) << what;
  }
}

// --- write_posed_mesh ---

TEST(ExportPosedMeshTest, ObjAndPlyReadBackAsTheOptimisedMesh) {
  const PosedMesh mesh = shuffled_grid(15, 4, 9);
  const PosedMesh optimised = optimise_for_rendering(mesh);
  TempDir dir;
  for (const std::string name : {"posed.obj", "posed.PLY", "posed.Obj"}) {
    const auto path = dir / name;
    const Status status = write_posed_mesh(path, mesh);
    ASSERT_TRUE(status.ok()) << status.error().message;
    const auto read = mesh_io::read_triangle_mesh(path);
    ASSERT_TRUE(read.ok()) << read.error().message;
    ASSERT_EQ(read->V.rows(), optimised.points.rows()) << name;
    ASSERT_EQ(read->F.rows(), optimised.faces.rows()) << name;
    EXPECT_TRUE(read->V == optimised.points) << name;
    EXPECT_TRUE(read->F == optimised.faces) << name;
  }
}

// The normals an OBJ file holds, read here without the library's reader (which keeps none):
// `vn` lines in order, and every face corner must name its vertex's own normal (`v//vn`, v = vn).
PointMatrix obj_normals(const std::string& text, Eigen::Index faces_expected) {
  std::vector<std::array<float, 3>> normals;
  Eigen::Index faces = 0;
  int corners_without_normal = 0;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string tag;
    words >> tag;
    if (tag == "vn") {
      std::array<float, 3> n{};
      words >> n[0] >> n[1] >> n[2];
      normals.push_back(n);
    } else if (tag == "f") {
      ++faces;
      std::string corner;
      while (words >> corner) {
        const auto slashes = corner.find("//");
        if (slashes == std::string::npos) {
          ++corners_without_normal;
        } else {
          EXPECT_EQ(corner.substr(0, slashes), corner.substr(slashes + 2)) << line;
        }
      }
    }
  }
  EXPECT_EQ(faces, faces_expected);
  EXPECT_EQ(corners_without_normal, 0) << "face corners that name no normal";
  PointMatrix out(static_cast<Eigen::Index>(normals.size()), 3);
  for (size_t v = 0; v < normals.size(); ++v) out.row(static_cast<Eigen::Index>(v)) << normals[v][0], normals[v][1], normals[v][2];
  return out;
}

// The vertex records of a binary PLY whose vertex element is `properties` float32 values each.
PointMatrix ply_vertex_columns(const std::string& bytes, const std::vector<std::string>& properties, int first,
                               Eigen::Index vertices) {
  const auto end = bytes.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end);
  std::string expected_properties;
  for (const std::string& name : properties) expected_properties += "property float " + name + "\n";
  EXPECT_NE(header.find("element vertex " + std::to_string(vertices) + "\n" + expected_properties + "element face"),
            std::string::npos)
      << header;
  PointMatrix out(vertices, 3);
  const char* records = bytes.data() + end + std::strlen("end_header\n");
  for (Eigen::Index v = 0; v < vertices; ++v) {
    for (int c = 0; c < 3; ++c) {
      float value = 0;
      const size_t column = static_cast<size_t>(first + c);
      std::memcpy(&value, records + sizeof(float) * (static_cast<size_t>(v) * properties.size() + column), sizeof value);
      out(v, c) = value;
    }
  }
  return out;
}

TEST(ExportPosedMeshTest, ObjAndPlyCarryTheNormalsWhenTheMeshHasThem) {
  const PosedMesh mesh = shuffled_grid(9, 2, 12);
  const PosedMesh optimised = optimise_for_rendering(mesh);
  TempDir dir;
  ASSERT_TRUE(write_posed_mesh(dir / "n.obj", mesh).ok());
  const auto obj = read_whole_file(dir / "n.obj");
  ASSERT_TRUE(obj.ok());
  const PointMatrix obj_n = obj_normals(*obj, optimised.faces.rows());
  EXPECT_TRUE(obj_n == optimised.normals) << "OBJ normals, in vertex order, bit for bit";
  const auto read_obj = mesh_io::read_triangle_mesh(dir / "n.obj");  // v//vn corners still read as faces
  ASSERT_TRUE(read_obj.ok()) << read_obj.error().message;
  EXPECT_TRUE(read_obj->F == optimised.faces);

  ASSERT_TRUE(write_posed_mesh(dir / "n.ply", mesh).ok());
  const auto ply = read_whole_file(dir / "n.ply");
  ASSERT_TRUE(ply.ok());
  const std::vector<std::string> with_normals = {"x", "y", "z", "nx", "ny", "nz"};
  EXPECT_TRUE(ply_vertex_columns(*ply, with_normals, 0, optimised.points.rows()) == optimised.points);
  EXPECT_TRUE(ply_vertex_columns(*ply, with_normals, 3, optimised.points.rows()) == optimised.normals);
  const auto read_ply = mesh_io::read_triangle_mesh(dir / "n.ply");  // extra properties are skipped
  ASSERT_TRUE(read_ply.ok()) << read_ply.error().message;
  EXPECT_TRUE(read_ply->V == optimised.points);
  EXPECT_TRUE(read_ply->F == optimised.faces);

  // Without normals: no vn lines, plain corners, x y z only.
  PosedMesh bare = mesh;
  bare.normals.resize(0, 3);
  ASSERT_TRUE(write_posed_mesh(dir / "bare.obj", bare).ok());
  ASSERT_TRUE(write_posed_mesh(dir / "bare.ply", bare).ok());
  const auto bare_obj = read_whole_file(dir / "bare.obj");
  ASSERT_TRUE(bare_obj.ok());
  EXPECT_EQ(bare_obj->find("vn "), std::string::npos);
  EXPECT_EQ(bare_obj->find("//"), std::string::npos);
  const auto bare_ply = read_whole_file(dir / "bare.ply");
  ASSERT_TRUE(bare_ply.ok());
  EXPECT_TRUE(ply_vertex_columns(*bare_ply, {"x", "y", "z"}, 0, optimised.points.rows()) == optimised.points);
}

TEST(ExportPosedMeshTest, GlbAndGltfFilesReadBack) {
  const PosedMesh mesh = shuffled_grid(12, 3, 10);
  const PosedMesh optimised = optimise_for_rendering(mesh);
  TempDir dir;
  ASSERT_TRUE(write_posed_mesh(dir / "posed.glb", mesh).ok());
  ASSERT_TRUE(write_posed_mesh(dir / "posed.GLTF", mesh).ok());
  const auto glb_bytes = read_whole_file(dir / "posed.glb");
  ASSERT_TRUE(glb_bytes.ok());
  EXPECT_EQ(*glb_bytes, *serialize_glb(optimised));
  const LoadedGltf glb = load_glb(*glb_bytes);
  ASSERT_TRUE(glb.ok) << glb.error;
  expect_document_matches(glb.model, optimised);
  const auto gltf_text = read_whole_file(dir / "posed.GLTF");
  ASSERT_TRUE(gltf_text.ok());
  const LoadedGltf gltf = load_gltf(*gltf_text);
  ASSERT_TRUE(gltf.ok) << gltf.error;
  expect_document_matches(gltf.model, optimised);
}

TEST(ExportPosedMeshTest, UnknownExtensionAndUnwritablePath) {
  const PosedMesh mesh = shuffled_grid(5, 0, 11);
  TempDir dir;
  for (const std::string name : {"posed.stl", "posed", "posed.off", "posed.glb.bak"}) {
    const Status status = write_posed_mesh(dir / name, mesh);
    ASSERT_FALSE(status.ok()) << name;
    EXPECT_EQ(status.error().code, ErrorCode::kInvalidArgument) << name;
    EXPECT_NE(status.error().message.find(name), std::string::npos) << status.error().message;
    EXPECT_FALSE(std::filesystem::exists(dir / name));
  }
  const Status missing_dir = write_posed_mesh(dir / "no" / "such" / "posed.glb", mesh);
  ASSERT_FALSE(missing_dir.ok());
  EXPECT_EQ(missing_dir.error().code, ErrorCode::kIo);
}

}  // namespace
}  // namespace animspace::mesh_io
