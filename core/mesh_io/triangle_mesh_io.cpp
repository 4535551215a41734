#include "core/mesh_io/triangle_mesh_io.h"

// OpenMesh wants its IO header before any mesh kernel header.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include <bit>
#include <cmath>
#include <cstdint>
#include <exception>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "core/common/atomic_file.h"
#include "core/mesh_io/text_io.h"

namespace animspace::mesh_io {
namespace {

static_assert(std::endian::native == std::endian::little,
              "binary PLY is written by copying little endian float32/int32 memory");

enum class MeshFormat { kObj, kPly, kOff };

Result<MeshFormat> format_of(const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".obj") return MeshFormat::kObj;
  if (extension == ".ply") return MeshFormat::kPly;
  if (extension == ".off") return MeshFormat::kOff;
  return make_error(ErrorCode::kInvalidArgument,
                    path.string() + ": unknown mesh file extension '" + path.extension().string() +
                        "' (supported: .obj, .ply, .off)");
}

// Appends the fan triangulation of one polygon, (a b c d …) → (a b c) (a c d) …
void append_fan(const std::vector<int32_t>& polygon, std::vector<int32_t>& triangles) {
  for (size_t k = 1; k + 1 < polygon.size(); ++k) {
    triangles.insert(triangles.end(), {polygon[0], polygon[k], polygon[k + 1]});
  }
}

TriangleMesh to_mesh(const std::vector<float>& points, const std::vector<int32_t>& triangles) {
  TriangleMesh mesh;
  mesh.V = Eigen::Map<const PointMatrix>(points.data(), static_cast<Eigen::Index>(points.size() / 3), 3);
  mesh.F = Eigen::Map<const FaceMatrix>(triangles.data(), static_cast<Eigen::Index>(triangles.size() / 3), 3);
  return mesh;
}

// One corner of an OBJ face, `v`, `v/vt`, `v//vn` or `v/vt/vn`, as a zero-based vertex index.
// `vertex_count` is the number of vertices defined above the face (what negative indices count
// back from, and the most a positive one may reach).
Result<int32_t> parse_face_corner(const TextReader& in, std::string_view corner, int vertex_count) {
  constexpr std::string_view kCornerForms = "a face corner v, v/vt, v//vn or v/vt/vn";
  std::string_view parts[3];
  int part_count = 0;
  for (std::string_view rest = corner;; ++part_count) {
    if (part_count == 3) return in.error(kCornerForms, corner);
    const size_t slash = rest.find('/');
    parts[part_count] = rest.substr(0, slash);
    if (slash == std::string_view::npos) {
      ++part_count;
      break;
    }
    rest.remove_prefix(slash + 1);
  }
  // Only v//vn may leave a part empty; texture and normal indices are checked, not kept.
  const bool well_formed = !parts[0].empty() && (part_count < 2 || !parts[part_count - 1].empty());
  if (!well_formed) return in.error(kCornerForms, corner);
  for (int k = 1; k < part_count; ++k) {
    if (!parts[k].empty() && !in.parse<int>(parts[k], kCornerForms).ok()) return in.error(kCornerForms, corner);
  }
  auto index = in.parse<int>(parts[0], kCornerForms);
  if (!index.ok()) return index.error();
  // OBJ indices are 1-based; negative ones are relative to the latest vertex (B1 "Referencing
  // groups of vertices").
  const int64_t resolved = *index > 0 ? int64_t{*index} - 1 : int64_t{vertex_count} + *index;
  if (*index == 0 || resolved < 0 || resolved >= vertex_count) {
    const std::string count = std::to_string(vertex_count);
    return in.error(vertex_count == 0 ? std::string("a vertex index, but no vertex is defined above this face")
                                      : "a vertex index in 1.." + count + " or -" + count + "..-1 (" + count +
                                            " vertices defined so far)",
                    parts[0]);
  }
  return static_cast<int32_t>(resolved);
}

// Records the vertices and polygons OpenMesh's PLY/OFF readers report, in file order. The base
// ImporterT still builds the TriMesh the readers need for properties, but a half-edge mesh
// cannot hold every triangle soup: it duplicates the vertices of non-manifold faces and drops
// faces that repeat a vertex. Taking points and polygons from here keeps the file's vertex
// numbering — which a point cache relies on — and all of its faces.
class RecordingImporter final : public OpenMesh::IO::ImporterT<OpenMesh::TriMesh_ArrayKernelT<>> {
 public:
  using Base = OpenMesh::IO::ImporterT<OpenMesh::TriMesh_ArrayKernelT<>>;
  explicit RecordingImporter(OpenMesh::TriMesh_ArrayKernelT<>& mesh) : Base(mesh) {}

  OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3f& point) override {
    ++file_vertex_count_;
    return Base::add_vertex(point);
  }
  OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3d& point) override {
    ++file_vertex_count_;
    return Base::add_vertex(point);
  }
  OpenMesh::VertexHandle add_vertex() override {
    ++file_vertex_count_;
    return Base::add_vertex();
  }
  OpenMesh::FaceHandle add_face(const VHandles& corners) override {
    std::vector<int32_t> polygon;
    polygon.reserve(corners.size());
    for (const auto& corner : corners) polygon.push_back(corner.idx());
    polygons_.push_back(std::move(polygon));
    return Base::add_face(corners);
  }

  int file_vertex_count() const { return file_vertex_count_; }
  const std::vector<std::vector<int32_t>>& polygons() const { return polygons_; }

 private:
  int file_vertex_count_ = 0;
  std::vector<std::vector<int32_t>> polygons_;
};

// Element counts a PLY or OFF header declares.
struct DeclaredCounts {
  int vertices = 0;
  int faces = 0;
};

// OpenMesh's readers trust the header: a garbage count makes them reserve gigabytes, and a short
// file is padded with stale values rather than refused. So the header is read here first, and
// every element must have at least one byte of data behind the header before OpenMesh runs.
Status check_counts_fit(const DeclaredCounts& counts, std::string_view body, const TextReader& in) {
  if (counts.vertices < 0 || counts.faces < 0) {
    return in.error("non-negative element counts", std::to_string(counts.vertices) + " vertices, " +
                                                       std::to_string(counts.faces) + " faces");
  }
  if (int64_t{counts.vertices} + counts.faces > static_cast<int64_t>(body.size())) {
    return in.error("element counts that fit in the " + std::to_string(body.size()) + " bytes of data",
                    std::to_string(counts.vertices) + " vertices, " + std::to_string(counts.faces) + " faces");
  }
  return Status::Ok();
}

// PLY header: `ply`, `format …`, `element <name> <count>` and `property …` lines, `end_header`.
Result<DeclaredCounts> declared_ply_counts(std::string_view bytes, std::string_view source) {
  TextReader in(bytes, source);
  if (!in.next_line()) return in.error("expected 'ply' on the first line, got end of file");
  if (const std::string_view magic = in.next_token(); magic != "ply") return in.error("'ply' on the first line", magic);
  DeclaredCounts counts;
  while (in.next_line()) {
    const std::string_view keyword = in.next_token();
    if (keyword == "end_header") {
      ANIMSPACE_RETURN_IF_ERROR(check_counts_fit(counts, in.rest_after_line(), in));
      return counts;
    }
    if (keyword != "element") continue;
    const std::string_view name = in.next_token();
    const auto count = in.read<int>("an element count");
    if (!count.ok()) return count.error();
    if (name == "vertex") counts.vertices = *count;
    if (name == "face") counts.faces = *count;
  }
  return in.error("expected 'end_header', got end of file");
}

// OFF header: `OFF` (or a variant such as COFF, NOFF) alone on the first line, then
// `#vertices #faces #edges`. Stricter than the format: OpenMesh's reader loops forever on a comment
// before the keyword and reads nothing from counts on the keyword's line or after a comment.
Result<DeclaredCounts> declared_off_counts(std::string_view bytes, std::string_view source) {
  TextReader in(bytes, source);
  if (!in.next_line()) return in.error("expected 'OFF', got end of file");
  const std::string_view keyword = in.next_token();
  if (!keyword.ends_with("OFF")) return in.error("'OFF' on the first line", keyword);
  if (const std::string_view rest = in.next_token(); rest == "BINARY") {
    return in.error("text OFF (binary OFF is not supported)", rest);
  } else if (!rest.empty()) {
    return in.error("end of line after '" + std::string(keyword) + "' (the counts go on the next line)", rest);
  }
  DeclaredCounts counts;
  for (int* count : {&counts.vertices, &counts.faces}) {
    const auto value = in.parse<int>(in.next_token_any_line(), "the vertex and face counts");
    if (!value.ok()) return value.error();
    *count = *value;
  }
  ANIMSPACE_RETURN_IF_ERROR(check_counts_fit(counts, in.rest_after_line(), in));
  return counts;
}

Result<TriangleMesh> read_with_openmesh(std::string_view bytes, MeshFormat format, const std::string& source) {
  const auto declared = format == MeshFormat::kPly ? declared_ply_counts(bytes, source) : declared_off_counts(bytes, source);
  if (!declared.ok()) return declared.error();

  OpenMesh::TriMesh_ArrayKernelT<> trimesh;
  RecordingImporter importer(trimesh);
  OpenMesh::IO::Options options;
  // OpenMesh's OFF reader fails the stream on a last line without '\n'; a final newline changes
  // nothing else, for text or binary.
  std::string text(bytes);
  if (text.back() != '\n') text += '\n';
  std::istringstream stream(std::move(text), std::ios::in | std::ios::binary);
  // From a stream the reader is chosen by the extension given, whatever the file name's case.
  const std::string extension = format == MeshFormat::kPly ? "ply" : "off";
  if (!OpenMesh::IO::IOManager().read(stream, extension, importer, options)) {
    return make_error(ErrorCode::kInvalidArgument, source + ": OpenMesh could not read it as " + extension);
  }
  // A reader that ran out of data or met a non-number (e.g. "nan") leaves the stream failed.
  if (stream.fail()) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": truncated or malformed " + extension + " data (a value could not be read)");
  }
  if (importer.file_vertex_count() != declared->vertices || importer.polygons().size() != static_cast<size_t>(declared->faces)) {
    return make_error(ErrorCode::kInvalidArgument,
                      source + ": the header declares " + std::to_string(declared->vertices) + " vertices and " +
                          std::to_string(declared->faces) + " faces, OpenMesh read " +
                          std::to_string(importer.file_vertex_count()) + " and " +
                          std::to_string(importer.polygons().size()));
  }
  const int vertex_count = importer.file_vertex_count();
  if (vertex_count == 0) return make_error(ErrorCode::kInvalidArgument, source + ": no vertices");

  std::vector<float> points;
  points.reserve(3 * static_cast<size_t>(vertex_count));
  for (int v = 0; v < vertex_count; ++v) {
    const auto& point = trimesh.point(OpenMesh::VertexHandle(v));
    if (!std::isfinite(point[0]) || !std::isfinite(point[1]) || !std::isfinite(point[2])) {
      return make_error(ErrorCode::kInvalidArgument,
                        source + ": vertex " + std::to_string(v) + " (zero-based) has a non-finite coordinate");
    }
    points.insert(points.end(), {point[0], point[1], point[2]});
  }
  std::vector<int32_t> triangles;
  for (size_t f = 0; f < importer.polygons().size(); ++f) {
    const auto& polygon = importer.polygons()[f];
    for (const int32_t corner : polygon) {
      if (corner < 0 || corner >= vertex_count) {
        return make_error(ErrorCode::kInvalidArgument,
                          source + ": face " + std::to_string(f) + " (zero-based) refers to vertex " +
                              std::to_string(corner) + ", expected 0.." + std::to_string(vertex_count - 1));
      }
    }
    if (polygon.size() < 3) {
      return make_error(ErrorCode::kInvalidArgument, source + ": face " + std::to_string(f) +
                                                         " (zero-based) has " + std::to_string(polygon.size()) +
                                                         " vertices, expected at least 3");
    }
    append_fan(polygon, triangles);
  }
  return to_mesh(points, triangles);
}

Status check_writable(const TriangleMesh& mesh, const std::string& destination) {
  if (mesh.V.rows() == 0) return make_error(ErrorCode::kInvalidArgument, destination + ": mesh has no vertices");
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v) {
    if (!mesh.V.row(v).allFinite()) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": vertex " + std::to_string(v) + " has a non-finite coordinate");
    }
  }
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    if (mesh.F.row(f).minCoeff() < 0 || mesh.F.row(f).maxCoeff() >= mesh.V.rows()) {
      return make_error(ErrorCode::kInvalidArgument,
                        destination + ": face " + std::to_string(f) + " has a vertex index outside 0.." +
                            std::to_string(mesh.V.rows() - 1));
    }
  }
  return Status::Ok();
}

// Text lines "<prefix> x y z" and "<prefix> a b c" (indices shifted by `index_base`).
void append_vertex_lines(const PointMatrix& V, std::string_view prefix, std::string& out) {
  for (Eigen::Index v = 0; v < V.rows(); ++v) {
    out += prefix;
    for (int axis = 0; axis < 3; ++axis) {
      append_number(out, V(v, axis));
      out += axis < 2 ? ' ' : '\n';
    }
  }
}
void append_face_lines(const FaceMatrix& F, std::string_view prefix, int index_base, std::string& out) {
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    out += prefix;
    for (int corner = 0; corner < 3; ++corner) {
      append_number(out, F(f, corner) + index_base);
      out += corner < 2 ? ' ' : '\n';
    }
  }
}

std::string serialize_obj(const TriangleMesh& mesh) {
  std::string out;
  append_vertex_lines(mesh.V, "v ", out);
  append_face_lines(mesh.F, "f ", 1, out);
  return out;
}

std::string serialize_off(const TriangleMesh& mesh) {
  std::string out = "OFF\n" + std::to_string(mesh.V.rows()) + ' ' + std::to_string(mesh.F.rows()) + " 0\n";
  append_vertex_lines(mesh.V, "", out);
  append_face_lines(mesh.F, "3 ", 0, out);
  return out;
}

std::string serialize_binary_ply(const TriangleMesh& mesh) {
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(mesh.V.rows()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(mesh.F.rows()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  // V is row-major float32: its memory is the vertex element's x y z records.
  out.append(reinterpret_cast<const char*>(mesh.V.data()), sizeof(float) * static_cast<size_t>(mesh.V.size()));
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    out += static_cast<char>(3);
    out.append(reinterpret_cast<const char*>(mesh.F.row(f).data()), 3 * sizeof(int32_t));
  }
  return out;
}

}  // namespace

Result<TriangleMesh> parse_obj(std::string_view text, std::string_view source) {
  std::vector<float> points;        // x y z per vertex
  std::vector<int32_t> triangles;   // a b c per triangle, zero-based
  std::vector<int32_t> polygon;     // the face being read
  TextReader in(text, source);
  while (in.next_line()) {
    const std::string_view keyword = in.next_token();
    if (keyword == "v") {
      for (int axis = 0; axis < 3; ++axis) {
        const auto coordinate = in.read<float>("a vertex coordinate");
        if (!coordinate.ok()) return coordinate.error();
        points.push_back(*coordinate);
      }
      for (std::string_view extra = in.next_token(); !extra.empty(); extra = in.next_token()) {
        if (const auto value = in.parse<float>(extra, "a number (w or vertex colour) or end of line"); !value.ok()) {
          return value.error();
        }
      }
    } else if (keyword == "f") {
      const auto vertex_count = static_cast<int>(points.size() / 3);
      polygon.clear();
      for (std::string_view corner = in.next_token(); !corner.empty(); corner = in.next_token()) {
        const auto index = parse_face_corner(in, corner, vertex_count);
        if (!index.ok()) return index.error();
        polygon.push_back(*index);
      }
      if (polygon.size() < 3) {
        return in.error("expected a face with at least 3 vertices, got " + std::to_string(polygon.size()));
      }
      append_fan(polygon, triangles);
    }
  }
  if (points.empty()) {
    return make_error(ErrorCode::kInvalidArgument, std::string(source) + ": no vertices ('v' lines)");
  }
  return to_mesh(points, triangles);
}

Result<TriangleMesh> read_triangle_mesh(const std::filesystem::path& path) {
  const auto format = format_of(path);
  if (!format.ok()) return format.error();
  const auto bytes = read_whole_file(path);
  if (!bytes.ok()) return bytes.error();
  try {
    switch (*format) {
      case MeshFormat::kObj: return parse_obj(*bytes, path.string());
      case MeshFormat::kPly:
      case MeshFormat::kOff: return read_with_openmesh(*bytes, *format, path.string());
    }
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory while reading");
  } catch (const std::exception& e) {
    return make_error(ErrorCode::kInvalidArgument, path.string() + ": " + e.what());
  }
  return make_error(ErrorCode::kInternal, path.string() + ": unhandled mesh format");
}

Status write_triangle_mesh(const std::filesystem::path& path, const TriangleMesh& mesh) {
  const auto format = format_of(path);
  if (!format.ok()) return format.error();
  ANIMSPACE_RETURN_IF_ERROR(check_writable(mesh, path.string()));
  try {
    switch (*format) {
      case MeshFormat::kObj: return write_file_atomically(path, serialize_obj(mesh));
      case MeshFormat::kPly: return write_file_atomically(path, serialize_binary_ply(mesh));
      case MeshFormat::kOff: return write_file_atomically(path, serialize_off(mesh));
    }
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::kResourceExhausted, path.string() + ": out of memory while writing");
  }
  return make_error(ErrorCode::kInternal, path.string() + ": unhandled mesh format");
}

}  // namespace animspace::mesh_io
