#include "core/mesh_io/triangle_mesh_io.h"

#include <array>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace animspace::mesh_io {
namespace {

using animspace::testing::TempDir;
using animspace::testing::write_text_file;

FaceMatrix faces(std::initializer_list<std::array<int32_t, 3>> rows) {
  FaceMatrix F(static_cast<Eigen::Index>(rows.size()), 3);
  Eigen::Index f = 0;
  for (const auto& row : rows) F.row(f++) << row[0], row[1], row[2];
  return F;
}

// A unit tetrahedron, outward-facing, with coordinates that are not short decimals.
TriangleMesh tetrahedron() {
  TriangleMesh mesh;
  mesh.V.resize(4, 3);
  mesh.V << 0.1f, -1.0f / 3.0f, 1e-7f,                  //
      123456.789f, std::numeric_limits<float>::denorm_min(), -0.0f,  //
      -2.5e-30f, 3.4e38f, 7.0f,                          //
      std::nextafter(1.0f, 2.0f), -std::nextafter(1.0f, 0.0f), 42.0f;
  mesh.F = faces({{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}});
  return mesh;
}

// Bitwise comparison: -0.0 and denormals must survive too.
void expect_same_bits(const PointMatrix& expected, const PointMatrix& actual) {
  ASSERT_EQ(expected.rows(), actual.rows());
  for (Eigen::Index i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(std::bit_cast<uint32_t>(expected.data()[i]), std::bit_cast<uint32_t>(actual.data()[i]))
        << "value " << i << ": expected " << expected.data()[i] << ", got " << actual.data()[i];
  }
}

TEST(ObjParse, ReadsVerticesAndOneBasedFaces) {
  const auto mesh = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n", "t.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  PointMatrix V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  EXPECT_EQ(mesh->V, V);
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}, {0, 2, 3}}));
}

TEST(ObjParse, ParsesDecimalsToTheNearestFloat) {
  // Long decimals as in the cow data; strtof is the independent reference.
  const auto mesh = parse_obj("v 39.537089999999999 -12.095312 1e-3\n", "t.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->V(0, 0), std::strtof("39.537089999999999", nullptr));
  EXPECT_EQ(mesh->V(0, 1), std::strtof("-12.095312", nullptr));
  EXPECT_EQ(mesh->V(0, 2), std::strtof("1e-3", nullptr));
}

TEST(ObjParse, AcceptsEveryCornerForm) {
  const std::string vertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n";
  for (const char* face : {"f 1 2 3", "f 1/1 2/2 3/3", "f 1//1 2//1 3//1", "f 1/1/1 2/2/1 3/3/1", "f 1/1 2//1 3/3/1"}) {
    const auto mesh = parse_obj(vertices + face + "\n", "t.obj");
    ASSERT_TRUE(mesh.ok()) << face << ": " << mesh.error().message;
    EXPECT_EQ(mesh->F, faces({{0, 1, 2}})) << face;
  }
}

TEST(ObjParse, NegativeIndicesCountBackFromTheLatestVertex) {
  // Each face uses the three vertices just above it.
  const auto mesh =
      parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 0 0\nv 6 0 0\nv 7 0 0\nf -3 -2 -1\nf -6 1 -1\n", "t.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}, {3, 4, 5}, {0, 0, 5}}));
}

TEST(ObjParse, FanTriangulatesPolygons) {
  const auto mesh = parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0.5 0\nf 1 2 3 4\nf 1 2 3 4 5\n", "t.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}, {0, 2, 3}, {0, 1, 2}, {0, 2, 3}, {0, 3, 4}}));
}

TEST(ObjParse, IgnoresOtherStatementsCommentsBlankLinesAndCarriageReturns) {
  const auto mesh = parse_obj(
      "# exported\r\nmtllib a.mtl\r\no cube\r\ng body\r\n\r\nv 1 2 3\r\nvt 0.5 0.5\r\nvn 0 0 1\r\nv 4 5 6 1\r\n"
      "v 7 8 9 0.1 0.2 0.3\r\nusemtl skin\r\ns off\r\nl 1 2\r\np 1\r\nf 1 2 3\r\n",
      "t.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  PointMatrix V(3, 3);
  V << 1, 2, 3, 4, 5, 6, 7, 8, 9;
  EXPECT_EQ(mesh->V, V);
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}}));
}

TEST(ObjParse, VerticesWithoutFacesAreAPointCloud) {
  const auto mesh = parse_obj("v 1 2 3\nv 4 5 6", "t.obj");  // no final newline either
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->V.rows(), 2);
  EXPECT_EQ(mesh->F.rows(), 0);
}

struct BadObj {
  const char* name;
  const char* text;
  const char* message;  // the error must contain this
};

class ObjParseErrors : public ::testing::TestWithParam<BadObj> {};

TEST_P(ObjParseErrors, NameFileLineExpectedAndFound) {
  const auto mesh = parse_obj(GetParam().text, "bad.obj");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(mesh.error().message.find(GetParam().message), std::string::npos) << mesh.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, ObjParseErrors,
    ::testing::Values(
        BadObj{"MissingCoordinate", "v 1 2\n", "bad.obj:1: expected a vertex coordinate, got end of line"},
        BadObj{"MalformedNumber", "v 0 0 0\nv 1 2.5.1 3\n", "bad.obj:2: expected a vertex coordinate, got '2.5.1'"},
        BadObj{"TrailingGarbage", "v 1 2 3 abc\n", "bad.obj:1: expected a number (w or vertex colour)"},
        BadObj{"NotANumber", "v nan 0 0\n", "bad.obj:1: expected a vertex coordinate, got 'nan'"},
        BadObj{"Infinite", "v 0 inf 0\n", "got 'inf'"},
        BadObj{"BeyondFloat", "v 0 0 1e39\n", "bad.obj:1: expected a vertex coordinate, got '1e39'"},
        BadObj{"IndexPastEnd", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
               "bad.obj:4: expected a vertex index in 1..3 or -3..-1 (3 vertices defined so far), got '4'"},
        BadObj{"ForwardReference", "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", "bad.obj:3: expected a vertex index in 1..2"},
        BadObj{"NegativePastStart", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "bad.obj:4:"},
        BadObj{"ZeroIndex", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "got '0'"},
        BadObj{"FaceBeforeVertices", "f 1 2 3\n", "bad.obj:1: expected a vertex index, but no vertex is defined"},
        BadObj{"TwoCorners", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2\n",
               "bad.obj:5: expected a face with at least 3 vertices, got 2"},
        BadObj{"EmptyFace", "v 0 0 0\nf\n", "bad.obj:2: expected a face with at least 3 vertices, got 0"},
        BadObj{"FourPartCorner", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n",
               "bad.obj:4: expected a face corner v, v/vt, v//vn or v/vt/vn, got '1/1/1/1'"},
        BadObj{"DanglingSlash", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2 3\n", "got '1/'"},
        BadObj{"NonNumericTexture", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n", "got '1/x'"},
        BadObj{"NonNumericIndex", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n", "bad.obj:4:"},
        BadObj{"NoVertices", "# nothing\n", "bad.obj: no vertices"}),
    [](const auto& test) { return std::string(test.param.name); });

TEST(MeshFile, UnknownExtensionNamesItAndTheSupportedOnes) {
  const auto mesh = read_triangle_mesh("model.stl");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(mesh.error().message.find("'.stl'"), std::string::npos) << mesh.error().message;
  EXPECT_NE(mesh.error().message.find(".obj, .ply, .off"), std::string::npos) << mesh.error().message;

  const TriangleMesh mesh_to_write = tetrahedron();
  TempDir dir;
  const Status written = write_triangle_mesh(dir / "model.glb", mesh_to_write);
  ASSERT_FALSE(written.ok());
  EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
}

TEST(MeshFile, MissingFileIsNotFound) {
  TempDir dir;
  const auto mesh = read_triangle_mesh(dir / "absent.obj");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kNotFound);
}

class MeshRoundTrip : public ::testing::TestWithParam<const char*> {};

TEST_P(MeshRoundTrip, WriteThenReadGivesIdenticalValues) {
  TempDir dir;
  const auto path = dir / (std::string("tetrahedron") + GetParam());
  const TriangleMesh mesh = tetrahedron();
  ASSERT_TRUE(write_triangle_mesh(path, mesh).ok());
  const auto read = read_triangle_mesh(path);
  ASSERT_TRUE(read.ok()) << read.error().message;
  expect_same_bits(mesh.V, read->V);
  EXPECT_EQ(read->F, mesh.F);
}

TEST_P(MeshRoundTrip, KeepsAPointCloud) {
  TempDir dir;
  const auto path = dir / (std::string("cloud") + GetParam());
  TriangleMesh cloud;
  cloud.V = tetrahedron().V;
  ASSERT_TRUE(write_triangle_mesh(path, cloud).ok());
  const auto read = read_triangle_mesh(path);
  ASSERT_TRUE(read.ok()) << read.error().message;
  expect_same_bits(cloud.V, read->V);
  EXPECT_EQ(read->F.rows(), 0);
}

TEST_P(MeshRoundTrip, KeepsNonManifoldFacesAndVertexNumbering) {
  // Three triangles on one edge (a "book"), plus an unused vertex: a half-edge mesh cannot hold
  // this without splitting vertices, a TriangleMesh must come back unchanged.
  TempDir dir;
  const auto path = dir / (std::string("book") + GetParam());
  TriangleMesh book;
  book.V.resize(6, 3);
  book.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, -1, 0, 9, 9, 9;
  book.F = faces({{0, 1, 2}, {1, 0, 3}, {0, 1, 4}});
  ASSERT_TRUE(write_triangle_mesh(path, book).ok());
  const auto read = read_triangle_mesh(path);
  ASSERT_TRUE(read.ok()) << read.error().message;
  expect_same_bits(book.V, read->V);
  EXPECT_EQ(read->F, book.F);
}

INSTANTIATE_TEST_SUITE_P(Formats, MeshRoundTrip, ::testing::Values(".obj", ".ply", ".off", ".OBJ", ".Ply", ".OFF"),
                         [](const auto& test) {
                           std::string name = test.param + 1;
                           return name + (std::isupper(static_cast<unsigned char>(test.param[1])) ? "Upper" : "");
                         });

TEST(MeshFile, WriteRefusesMeshesThatWouldNotReadBack) {
  TempDir dir;
  TriangleMesh out_of_range = tetrahedron();
  out_of_range.F(2, 1) = 4;
  TriangleMesh negative = tetrahedron();
  negative.F(0, 0) = -1;
  TriangleMesh not_finite = tetrahedron();
  not_finite.V(3, 2) = std::numeric_limits<float>::quiet_NaN();
  TriangleMesh empty;
  for (const TriangleMesh* mesh : {&out_of_range, &negative, &not_finite, &empty}) {
    const Status written = write_triangle_mesh(dir / "out.ply", *mesh);
    ASSERT_FALSE(written.ok());
    EXPECT_EQ(written.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(written.error().message.find("out.ply"), std::string::npos) << written.error().message;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.ply"));
}

TEST(OffRead, HandWrittenQuadIsFanTriangulated) {
  TempDir dir;
  write_text_file(dir / "quad.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0.5\n4 0 1 2 3\n");
  const auto mesh = read_triangle_mesh(dir / "quad.off");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  PointMatrix V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0.5f;
  EXPECT_EQ(mesh->V, V);
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}, {0, 2, 3}}));
}

TEST(PlyRead, HandWrittenAsciiQuadIsFanTriangulated) {
  TempDir dir;
  write_text_file(dir / "quad.ply",
                  "ply\nformat ascii 1.0\ncomment hand written\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                  "0 0 0\n1 0 0\n1 1 0\n0 1 0.25\n4 0 1 2 3\n");
  const auto mesh = read_triangle_mesh(dir / "quad.ply");
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  PointMatrix V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0.25f;
  EXPECT_EQ(mesh->V, V);
  EXPECT_EQ(mesh->F, faces({{0, 1, 2}, {0, 2, 3}}));
}

struct BadFile {
  const char* name;
  const char* file_name;
  const char* text;
  const char* message;
};

class PlyOffReadErrors : public ::testing::TestWithParam<BadFile> {};

TEST_P(PlyOffReadErrors, AreInvalidArgumentNamingTheFile) {
  TempDir dir;
  const auto path = dir / GetParam().file_name;
  write_text_file(path, GetParam().text);
  const auto mesh = read_triangle_mesh(path);
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(mesh.error().message.find(path.string()), std::string::npos) << mesh.error().message;
  EXPECT_NE(mesh.error().message.find(GetParam().message), std::string::npos) << mesh.error().message;
}

INSTANTIATE_TEST_SUITE_P(
    Table, PlyOffReadErrors,
    ::testing::Values(
        BadFile{"OffNotOff", "a.off", "garbage\n", ":1: expected 'OFF' on the first line, got 'garbage'"},
        BadFile{"OffEmpty", "a.off", "", "expected 'OFF'"},
        BadFile{"OffCommentFirst", "a.off", "# made by hand\nOFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n",
                ":1: expected 'OFF' on the first line, got '#'"},
        BadFile{"OffCountsOnKeywordLine", "a.off", "OFF 3 0 0\n0 0 0\n1 0 0\n0 1 0\n",
                ":1: expected end of line after 'OFF' (the counts go on the next line), got '3'"},
        BadFile{"OffCommentInHeader", "a.off", "OFF\n# counts\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n",
                ":2: expected the vertex and face counts, got '#'"},
        BadFile{"OffHugeCounts", "a.off", "OFF\n1000000000 1 0\n0 0 0\n", ":2: expected element counts that fit"},
        BadFile{"OffNegativeCount", "a.off", "OFF\n-3 0 0\n0 0 0\n", "non-negative"},
        BadFile{"OffTruncatedVertex", "a.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n1 1\n", "truncated or malformed"},
        BadFile{"OffMissingFace", "a.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n", "truncated or malformed"},
        BadFile{"OffNan", "a.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n1 nan 0\n", "truncated or malformed"},
        BadFile{"OffIndexOutOfRange", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 3\n",
                "face 0 (zero-based) refers to vertex 3, expected 0..2"},
        BadFile{"OffNoVertices", "a.off", "OFF\n0 0 0\n", "no vertices"},
        BadFile{"OffBinary", "a.off", "OFF BINARY\n", "binary OFF is not supported"},
        BadFile{"PlyNotPly", "a.ply", "solid cube\n", ":1: expected 'ply' on the first line, got 'solid'"},
        BadFile{"PlyNoEndHeader", "a.ply", "ply\nformat ascii 1.0\nelement vertex 0\n", "expected 'end_header'"},
        BadFile{"PlyHugeCount", "a.ply", "ply\nformat ascii 1.0\nelement vertex 2000000000\nend_header\n0 0 0\n",
                "expected element counts that fit"},
        BadFile{"PlyMissingFace", "a.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                           "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                                           "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
                "truncated or malformed"},
        BadFile{"PlyIndexOutOfRange", "a.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                               "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                               "end_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 7\n",
                "refers to vertex 7"},
        BadFile{"PlyNoVertices", "a.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                                          "property float z\nend_header\n",
                "no vertices"}),
    [](const auto& test) { return std::string(test.param.name); });

TEST(PlyRead, TruncatedBinaryIsRefused) {
  TempDir dir;
  const auto path = dir / "mesh.ply";
  ASSERT_TRUE(write_triangle_mesh(path, tetrahedron()).ok());
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  write_text_file(path, bytes.substr(0, bytes.size() - 5));
  const auto mesh = read_triangle_mesh(path);
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(mesh.error().message.find(path.string()), std::string::npos) << mesh.error().message;
}

}  // namespace
}  // namespace animspace::mesh_io
