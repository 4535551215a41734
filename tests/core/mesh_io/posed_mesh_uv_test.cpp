// Texture coordinates in the posed-mesh exports: seams split into vertices, OBJ `vt` per corner.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "core/mesh_io/posed_mesh.h"
#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

// Two triangles sharing the edge 0–2, in two charts: vertices 0 and 2 lie on the seam.
PosedMesh two_charts(UvMatrix& corner_uvs) {
  PosedMesh mesh;
  mesh.points.resize(4, 3);
  mesh.points << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  mesh.faces.resize(2, 3);
  mesh.faces << 0, 1, 2, 0, 2, 3;
  corner_uvs.resize(6, 2);
  corner_uvs << 0.1f, 0.1f, 0.4f, 0.1f, 0.4f, 0.4f,   // chart 0
      0.6f, 0.6f, 0.9f, 0.9f, 0.6f, 0.9f;            // chart 1
  return mesh;
}

TEST(PosedMeshUv, SeamsSplitVerticesAndKeepPositions) {
  UvMatrix corner_uvs;
  const PosedMesh mesh = two_charts(corner_uvs);
  const PosedMesh split = split_seams(mesh, corner_uvs);
  EXPECT_EQ(split.points.rows(), 6);  // 0 and 2 twice (one per chart), 1 and 3 once
  ASSERT_EQ(split.uvs.rows(), split.points.rows());
  for (Eigen::Index f = 0; f < 2; ++f) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(split.points.row(split.faces(f, k)), mesh.points.row(mesh.faces(f, k)));
      EXPECT_EQ(split.uvs.row(split.faces(f, k)), corner_uvs.row(3 * f + k));
    }
  }
}

TEST(PosedMeshUv, ObjHasAVtForEveryCornerWithItsUv) {
  UvMatrix corner_uvs;
  const PosedMesh mesh = two_charts(corner_uvs);
  const auto path = std::filesystem::temp_directory_path() / ("posed_mesh_uv_" + std::to_string(::getpid()) + ".obj");
  ASSERT_TRUE(write_posed_mesh(path, split_seams(mesh, corner_uvs)).ok());
  std::ifstream in(path);
  std::vector<Eigen::Vector3f> v;
  std::vector<Eigen::Vector2f> vt;
  std::vector<std::vector<std::pair<int, int>>> faces;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string tag;
    fields >> tag;
    if (tag == "v") {
      Eigen::Vector3f p;
      fields >> p.x() >> p.y() >> p.z();
      v.push_back(p);
    } else if (tag == "vt") {
      Eigen::Vector2f t;
      fields >> t.x() >> t.y();
      vt.push_back(t);
    } else if (tag == "f") {
      std::vector<std::pair<int, int>> corners;
      std::string corner;
      while (fields >> corner) {
        int a = 0, b = 0;
        ASSERT_EQ(std::sscanf(corner.c_str(), "%d/%d", &a, &b), 2) << "corner without vt: " << corner;
        corners.emplace_back(a - 1, b - 1);
      }
      faces.push_back(corners);
    }
  }
  std::filesystem::remove(path);
  EXPECT_EQ(vt.size(), 6u);
  ASSERT_EQ(faces.size(), 2u);
  // Match each written face to an input face by its corner positions, then compare the UVs.
  int matched = 0;
  for (Eigen::Index f = 0; f < 2; ++f) {
    for (const auto& written : faces) {
      for (int shift = 0; shift < 3; ++shift) {
        bool same = true;
        for (int k = 0; k < 3; ++k) {
          same = same && v[static_cast<size_t>(written[static_cast<size_t>((k + shift) % 3)].first)] ==
                             mesh.points.row(mesh.faces(f, k)).transpose();
        }
        if (!same) continue;
        ++matched;
        for (int k = 0; k < 3; ++k) {
          EXPECT_EQ(vt[static_cast<size_t>(written[static_cast<size_t>((k + shift) % 3)].second)],
                    corner_uvs.row(3 * f + k).transpose());
        }
      }
    }
  }
  EXPECT_EQ(matched, 2);
}

TEST(PosedMeshUv, GltfCarriesTexcoord0) {
  UvMatrix corner_uvs;
  const PosedMesh mesh = two_charts(corner_uvs);
  auto json = serialize_gltf(optimise_for_rendering(split_seams(mesh, corner_uvs)));
  ASSERT_TRUE(json.ok()) << json.error().message;
  EXPECT_NE(json->find("TEXCOORD_0"), std::string::npos);
}

TEST(PosedMeshUv, RefusesUvsOfTheWrongCount) {
  UvMatrix corner_uvs;
  PosedMesh mesh = two_charts(corner_uvs);
  mesh.uvs.resize(3, 2);
  mesh.uvs.setZero();
  EXPECT_FALSE(serialize_glb(mesh).ok());
}

}  // namespace
}  // namespace animspace::mesh_io
