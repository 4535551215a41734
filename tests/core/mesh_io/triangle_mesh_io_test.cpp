#include "core/mesh_io/triangle_mesh_io.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
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

// A unit square with a lifted corner, as the expected result of the hand-written files below.
TriangleMesh lifted_square() {
  TriangleMesh mesh;
  mesh.V.resize(4, 3);
  mesh.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0.25f;
  mesh.F = faces({{0, 1, 2}, {0, 2, 3}});
  return mesh;
}

struct GoodFile {
  const char* name;
  std::string text;
};

class PlyOffHandWritten : public ::testing::TestWithParam<GoodFile> {};

TEST_P(PlyOffHandWritten, ReadsAsTheLiftedSquare) {
  TempDir dir;
  const auto path = dir / GetParam().name;
  write_text_file(path, GetParam().text);
  const auto mesh = read_triangle_mesh(path);
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  EXPECT_EQ(mesh->V, lifted_square().V);
  EXPECT_EQ(mesh->F, lifted_square().F);
}

// Little/big endian bytes of a value, for hand-built binary PLY.
template <typename T>
std::string binary(T value, bool big_endian) {
  std::string bytes(sizeof(T), '\0');
  std::memcpy(bytes.data(), &value, sizeof(T));
  if (big_endian) std::reverse(bytes.begin(), bytes.end());
  return bytes;
}

// The lifted square as binary PLY with a colour per vertex, double coordinates, a short list
// length and an extra element to skip.
std::string binary_square_ply(bool big_endian) {
  std::string ply = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\ncomment made by hand\nelement vertex 4\nproperty double x\nproperty double y\n"
                    "property double z\nproperty uchar red\nelement face 1\nproperty list ushort uint vertex_indices\n"
                    "element extra 1\nproperty list uchar float values\nend_header\n";
  const double xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.25}};
  for (const auto& vertex : xyz) {
    for (const double coordinate : vertex) ply += binary(coordinate, big_endian);
    ply += '\xff';
  }
  ply += binary(uint16_t{4}, big_endian);
  for (const uint32_t index : {0u, 1u, 2u, 3u}) ply += binary(index, big_endian);
  ply += '\x02' + binary(1.5f, big_endian) + binary(-2.5f, big_endian);
  return ply;
}

INSTANTIATE_TEST_SUITE_P(
    Formats, PlyOffHandWritten,
    ::testing::Values(
        GoodFile{"square.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0.25\n4 0 1 2 3\n"},
        GoodFile{"commented.off", "# made by hand\nOFF\n# counts\n4 1 0\n\n0 0 0\n1 0 0 # a comment\n1 1 0\n0 1 0.25\n"
                                  "# faces\n4 0 1 2 3\n\n"},
        GoodFile{"counts_on_keyword_line.off", "OFF 4 1\n0 0 0\n1 0 0\n1 1 0\n0 1 0.25\n4 0 1 2 3"},
        GoodFile{"colours.off", "COFF\n4 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n"
                                "0 1 0.25 9 9 9 255\n4 0 1 2 3 0.5 0.5 0.5\n"},
        GoodFile{"crlf.off", "OFF\r\n4 1 0\r\n0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0.25\r\n4 0 1 2 3\r\n"},
        GoodFile{"square.ply",
                 "ply\nformat ascii 1.0\ncomment hand written\nelement vertex 4\nproperty float x\nproperty float y\n"
                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                 "0 0 0\n1 0 0\n1 1 0\n0 1 0.25\n4 0 1 2 3\n"},
        GoodFile{"extras.ply",
                 "ply\nformat ascii 1.0\nelement vertex 4\nproperty float32 nx\nproperty float64 z\nproperty float y\n"
                 "property uchar red\nproperty double x\nelement face 1\nproperty uchar flags\n"
                 "property list uint8 int32 vertex_index\nproperty list uchar float texcoord\nelement edge 1\n"
                 "property int vertex1\nproperty int vertex2\nend_header\n"
                 "1 0 0 255 0\n1 0 0 255 1\n1 0 1 255 1\n1 0.25 1 255 0\n7 4 0 1 2 3 2 0.5 0.5\n0 1"},
        GoodFile{"little_endian.ply", binary_square_ply(false)}, GoodFile{"big_endian.ply", binary_square_ply(true)}),
    [](const auto& test) {
      std::string name = test.param.name;
      std::replace(name.begin(), name.end(), '.', '_');
      return name;
    });

struct BadFile {
  const char* name;
  const char* file_name;
  std::string text;
  const char* message;  // after the file name
  ErrorCode code = ErrorCode::kInvalidArgument;
};

class PlyOffReadErrors : public ::testing::TestWithParam<BadFile> {};

TEST_P(PlyOffReadErrors, NameFileLineOrByteExpectedAndFound) {
  TempDir dir;
  const auto path = dir / GetParam().file_name;
  write_text_file(path, GetParam().text);
  const auto mesh = read_triangle_mesh(path);
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.error().code, GetParam().code) << mesh.error().message;
  EXPECT_NE(mesh.error().message.find(path.string() + GetParam().message), std::string::npos) << mesh.error().message;
}

// The tetrahedron as binary PLY: a 169-byte header, 4 × 12 vertex bytes, 4 × 13 face bytes (the
// last face: its length at byte 256, its indices at 257, 261 and 265).
const std::string kBinaryTetrahedron = serialize_ply(tetrahedron());

INSTANTIATE_TEST_SUITE_P(
    Table, PlyOffReadErrors,
    ::testing::Values(
        BadFile{"OffNotOff", "a.off", "garbage\n", ":1: expected 'OFF' (or COFF, NOFF, CNOFF, STOFF), got 'garbage'"},
        BadFile{"OffFourDimensional", "a.off", "4OFF\n1 0 0\n0 0 0 0\n", ":1: expected 'OFF'"},
        BadFile{"OffEmpty", "a.off", "", ": expected 'OFF', got end of file"},
        BadFile{"OffBinary", "a.off", "OFF BINARY\n", ":1: expected text OFF (binary OFF is not supported), got 'BINARY'"},
        BadFile{"OffNegativeCount", "a.off", "OFF\n-3 0 0\n", ":2: expected non-negative counts, got '-3 0'"},
        BadFile{"OffBadEdgeCount", "a.off", "OFF\n3 0 x\n", ":2: expected the edge count or end of line, got 'x'"},
        BadFile{"OffHugeCount", "a.off", "OFF\n1000000000 1 0\n0 0 0\n",
                ":3: expected 1000000000 vertices, got end of file after 1"},
        BadFile{"OffTruncatedVertex", "a.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n1 1\n",
                ":5: expected a vertex coordinate, got end of line"},
        BadFile{"OffMissingFace", "a.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n",
                ":6: expected 2 faces, got end of file after 1"},
        BadFile{"OffNan", "a.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n1 nan 0\n", ":5: expected a vertex coordinate, got 'nan'"},
        BadFile{"OffIndexOutOfRange", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 3\n",
                ":6: expected a vertex index in 0..2, got '3'"},
        BadFile{"OffTwoCornerFace", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n2 0 1\n",
                ":6: expected a face with at least 3 vertices, got '2'"},
        BadFile{"OffShortFace", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1\n",
                ":6: expected a vertex index in 0..2, got end of line"},
        BadFile{"OffTrailingData", "a.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n",
                ":6: expected end of file after 0 faces, got '3'"},
        BadFile{"OffNoVertices", "a.off", "OFF\n0 0 0\n", ": no vertices"},
        BadFile{"PlyNotPly", "a.ply", "solid cube\n", ":1: expected 'ply' on the first line, got 'solid'"},
        BadFile{"PlyNoFormat", "a.ply", "ply\nelement vertex 0\n", ":2: expected 'format' after 'ply', got 'element'"},
        BadFile{"PlyBadEncoding", "a.ply", "ply\nformat binary 1.0\n",
                ":2: expected ascii, binary_little_endian or binary_big_endian, got 'binary'"},
        BadFile{"PlyPropertyBeforeElement", "a.ply", "ply\nformat ascii 1.0\nproperty float x\n",
                ":3: expected an element before its properties, got 'property'"},
        BadFile{"PlyBadType", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\n",
                ":4: expected a PLY property type (char, uchar, …, float, double), got 'real'"},
        BadFile{"PlyFloatListLength", "a.ply",
                "ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n",
                ":4: expected an integral list length type, got 'float'"},
        BadFile{"PlyNoEndHeader", "a.ply", "ply\nformat ascii 1.0\nelement vertex 0\n",
                ":3: expected 'end_header', got end of file"},
        BadFile{"PlyNoCoordinates", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
                ":5: expected a vertex element with properties x, y and z in the header"},
        BadFile{"PlyNegativeListLength", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "element face 1\nproperty list char int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n-4 0 1 2 3\n",
                ":13: expected a non-negative list length, got -4"},
        BadFile{"PlyMissingFace", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n",
                ":13: expected a list length, got end of file"},
        BadFile{"PlyMalformedNumber", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "end_header\n0 0 0\n1 0-5\n1 1 0\n",
                ":9: expected a float value, got '0-5'"},
        BadFile{"PlyIndexOutOfRange", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 7\n",
                ":13: face 0: expected a vertex index in 0..2, got 7"},
        BadFile{"PlyFaceBeforeVertex", "a.ply",
                "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nelement vertex 1\n"
                "property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
                ":9: expected the face element after the vertex element"},
        BadFile{"PlyTrailingText", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                "end_header\n0 0 0\n1\n",
                ":9: expected end of file after the last element, got '1'"},
        BadFile{"PlyNoVertices", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
                "end_header\n",
                ": no vertices"},
        BadFile{"PlyBinaryTruncated", "a.ply", kBinaryTetrahedron.substr(0, kBinaryTetrahedron.size() - 5),
                ": byte 261: truncated: expected a vertex index (4 bytes), the file ends", ErrorCode::kDataLoss},
        BadFile{"PlyBinaryTrailing", "a.ply", kBinaryTetrahedron + "xyz",
                ": byte 269: trailing bytes: the elements end here, the file has 272 bytes", ErrorCode::kDataLoss},
        BadFile{"PlyBinaryNan", "a.ply",
                "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                "property float z\nend_header\n" +
                    std::string("\0\0\0\0\0\0\xc0\x7f\0\0\0\0", 12),
                ": byte 115: vertex 0 has a coordinate that is not a finite float32"},
        BadFile{"PlyBeyondFloat", "a.ply",
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\n"
                "end_header\n0 1e300 0\n",
                ":8: vertex 0 has a coordinate that is not a finite float32"}),
    [](const auto& test) { return std::string(test.param.name); });

}  // namespace
}  // namespace animspace::mesh_io
